"""Taichi's exception names catch simgrad's errors (`except ti.TaichiCompilationError` in existing programs),
and ti.set_logging_level takes Taichi's level names."""

from __future__ import annotations

import pytest

import simgrad as ti


def test_compile_errors_are_taichi_compilation_errors():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def bad():
        undefined_name_here += 1  # noqa: F821

    with pytest.raises(ti.TaichiCompilationError):
        bad()
    assert issubclass(ti.TaichiSyntaxError, ti.TaichiCompilationError) and issubclass(ti.TaichiSyntaxError,
                                                                                       SyntaxError)
    assert issubclass(ti.TaichiTypeError, TypeError) and issubclass(ti.TaichiIndexError, IndexError)
    assert issubclass(ti.TaichiNameError, NameError)


def test_runtime_errors_are_taichi_runtime_errors():
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.f32, 4)

    @ti.kernel
    def check(v: ti.f32):
        assert v > 0, "v must be positive"
        x[0] = v

    with pytest.raises(ti.TaichiAssertionError):
        check(-1.0)
    with pytest.raises(ti.TaichiRuntimeError):
        check(-1.0)
    assert issubclass(ti.GradientError, ti.TaichiRuntimeError)


def test_set_logging_level():
    from simgrad.lang import logging as lg

    for name in (ti.TRACE, ti.DEBUG, ti.INFO, ti.WARN, ti.ERROR, "warning"):
        ti.set_logging_level(name)
    assert lg.level == ti.WARN
    with pytest.raises(ValueError, match="unknown logging level"):
        ti.set_logging_level("loud")
    ti.set_logging_level(ti.INFO)


def test_gpu_scheduling_hints_run_and_change_nothing():
    ti.init(arch=ti.cpu)
    n = 16
    a = ti.field(ti.f32, n + 2)
    b = ti.field(ti.f32, n)

    @ti.kernel
    def blur():
        ti.block_local(a)
        ti.cache_read_only(a)
        for i in range(n):
            j = ti.assume_in_range(i + 1, i, 0, 2)
            b[i] = (a[j - 1] + a[j] + a[j + 1]) / 3

    import numpy as np

    av = np.arange(n + 2, dtype=np.float32) ** 2
    a.from_numpy(av)
    blur()
    np.testing.assert_allclose(b.to_numpy(), (av[:-2] + av[1:-1] + av[2:]) / 3, rtol=1e-6)


def test_no_activate_is_a_hint_on_the_cpu():
    # simulation/comet.py: `ti.no_activate(x)` before a struct-for over x (Taichi: accesses of x in this kernel
    # do not activate cells; the program promises they are active, so activating anyway computes the same)
    x = ti.field(ti.f32)
    ti.root.pointer(ti.i, 4).dense(ti.i, 4).place(x)
    y = ti.field(ti.f32, 16)

    @ti.kernel
    def step():
        ti.no_activate(x, y)
        for i in x:
            x[i] = x[i] * 2 + 1
            y[i] = x[i]

    x[3], x[9] = 1.0, 2.0
    step()
    assert x[3] == 3.0 and x[9] == 5.0 and y.to_numpy().sum() == 3 + 5 + 6 * 1
    with pytest.raises(TypeError, match="no_activate expects fields"):
        ti.no_activate(3)


# Taichi 1.7.4's public names (dir(taichi) without underscores), listed here so the test needs no taichi
TAICHI_1_7_4_NAMES = """ArgPack BitpackedFields CRITICAL DEBUG DeviceCapability ERROR Field FieldsBuilder Format GUI
INFO Layout Matrix MatrixField MatrixNdarray Mesh MeshInstance Ndarray SNode ScalarField ScalarNdarray Struct
StructField TRACE TaichiAssertionError TaichiCompilationError TaichiNameError TaichiRuntimeError
TaichiRuntimeTypeError TaichiSyntaxError TaichiTypeError Tape Texture Vector VectorNdarray WARN abs acos ad
activate algorithms amdgpu aot append arm64 asin assume_in_range atan2 atomic_add atomic_and atomic_max
atomic_min atomic_mul atomic_or atomic_sub atomic_xor axes bit_cast bit_shr block_local cache_read_only cast
ceil clear_all_gradients cos cpu cuda data_oriented dataclass deactivate deactivate_all_snodes dx11 dx12 eig
exp experimental extension f16 f32 f64 field float16 float32 float64 floor frexp func get_addr get_runtime
gles global_thread_idx gpu graph grouped hex_to_rgb i i16 i32 i64 i8 ij ijk ijkl ijl ik ikl il init int16
int32 int64 int8 is_active is_logging_effective j jk jkl jl k kernel kl l length linalg log loop_config
math max mesh_local mesh_patch_idx metal min ndarray ndrange no_activate one opengl polar_decompose pow
profiler pyfunc randn random raw_div raw_mod real_func ref rescale_index reset rgb_to_hex root round rsqrt
select set_logging_level sin solve sparse sparse_matrix_builder sqrt static static_assert static_print
stop_grad svd sym_eig sync tan tanh template tools types u1 u16 u32 u64 u8 ui uint1 uint16 uint32 uint64
uint8 vulkan x64 x86_64 zero""".split()


def test_every_taichi_name_exists_or_says_it_is_not_supported():
    missing, unsupported = [], []
    for name in TAICHI_1_7_4_NAMES:
        try:
            getattr(ti, name)
        except AttributeError:
            missing.append(name)
        except ti.SimgradNotSupportedError as e:
            assert "not supported" in str(e) and __file__.split("/")[-1] in str(e)  # located at this line
            unsupported.append(name)
    assert not missing, missing
    assert "data_oriented" not in unsupported and "ndarray" not in unsupported and len(unsupported) <= 27


def test_taichi_lang_ops_answers_under_its_taichi_name():
    """Taichi's own tests call `ti.lang.ops.add(u, v)` in kernels; simgrad's module is lang/operators.py."""
    ti.init(arch=ti.cpu)
    x = ti.Vector.field(3, dtype=int, shape=(16, 16))
    offsets = [ti.Vector([1, 2]), ti.Vector([2, 3])]

    @ti.kernel
    def k():
        vec = ti.Vector([4, 5])
        x[ti.lang.ops.add(vec, ti.static(offsets)[1])] = [1, 10, 100]
        x[ti.lang.ops.sub(vec, ti.static(offsets)[0])] = [7, 8, 9]

    k()
    assert x[6, 8].to_numpy().tolist() == [1, 10, 100]
    assert x[3, 3].to_numpy().tolist() == [7, 8, 9]


def test_lazy_names_are_kept_in_the_module_after_first_use():
    # ti.GUI, ti.Tape, ... load on first use (simgrad/__init__.py __getattr__) and are then plain attributes:
    # `ti.GUI.LEFT` in a frame loop must not go through the loader each time
    import simgrad.gui

    assert ti.GUI is simgrad.gui.GUI and vars(ti)["GUI"] is simgrad.gui.GUI
    assert ti.Tape is vars(ti)["Tape"]
    with pytest.raises(AttributeError):
        ti.no_such_name_anywhere  # noqa: B018
    assert "no_such_name_anywhere" not in vars(ti)
