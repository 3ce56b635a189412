"""The device interface (runtime/device.py): the host implementation, and the CUDA one where cuda-python and
a GPU exist."""

import ctypes

import numpy as np
import pytest

from simgrad.runtime import device


def test_host_driver_memory_and_copies():
    d = device.HostDriver()
    p = d.alloc(64)
    assert p % 64 == 0
    a = np.arange(16, dtype=np.float32)
    d.to_device(p, a)
    b = np.zeros(16, np.float32)
    d.to_host(b, p)
    assert (a == b).all()
    d.free(p)
    with pytest.raises(device.DeviceError, match="did not allocate"):
        d.free(p)
    e0 = d.event()
    d.synchronize()
    assert d.elapsed_ms(e0, d.event()) >= 0


def test_host_driver_bad_launch_is_located():
    d = device.HostDriver()
    with pytest.raises(device.DeviceError, match="invalid launch configuration") as e:
        d.launch(None, 1, 2048, 0)
    assert "test_device.py" in str(e.value)


class _FakeCu:
    """The two error-text calls of cuda.bindings.driver that CudaDriver._check makes (bytes, as cuda-python
    returns them), with the CUresult values the driver API documents."""

    NAMES = {2: b"CUDA_ERROR_OUT_OF_MEMORY", 700: b"CUDA_ERROR_ILLEGAL_ADDRESS", 710: b"CUDA_ERROR_ASSERT",
             701: b"CUDA_ERROR_LAUNCH_OUT_OF_RESOURCES"}

    def cuGetErrorName(self, err):
        return 0, self.NAMES[int(err)]

    def cuGetErrorString(self, err):
        return 0, b"text of " + self.NAMES[int(err)]


@pytest.mark.parametrize("code, cls, words", [
    (2, device.DeviceMemoryError, "CUDA_ERROR_OUT_OF_MEMORY (2)"),
    (701, device.DeviceError, "CUDA_ERROR_LAUNCH_OUT_OF_RESOURCES (701)"),
    (710, device.DeviceError, "a device-side assertion failed"),
    (700, device.DeviceError, "CUDA_ERROR_ILLEGAL_ADDRESS (700)"),
])
def test_cuda_errors_become_located_python_errors(code, cls, words):
    """Without a GPU: CudaDriver's result check on the driver's error codes (out of memory is also a MemoryError;
    a bad launch, an illegal address, a device-side assertion are DeviceErrors), located at the caller's line."""
    d = device.CudaDriver.__new__(device.CudaDriver)
    d.cu = _FakeCu()
    assert d._check((0, 42)) == 42 and d._check((0, 1, 2)) == (1, 2) and d._check((0,)) is None
    with pytest.raises(cls, match=words.replace("(", r"\(").replace(")", r"\)")) as e:
        d._check((code,))
    assert "test_device.py" in str(e.value)
    assert isinstance(e.value, MemoryError) == (code == 2)


@pytest.mark.skipif(not device.cuda_available(), reason="no CUDA driver/device (cuda-python) on this machine")
def test_cuda_driver_roundtrip_and_oom():
    d = device.CudaDriver()
    p = d.alloc(1024)
    a = np.arange(256, dtype=np.float32)
    d.to_device(p, a)
    b = np.zeros_like(a)
    d.to_host(b, p)
    assert (a == b).all()
    c = a + 1
    d.prepare_upload(p, c)()  # cuMemcpyHtoDAsync: c may change at once, the device has its bytes
    c[:] = 0
    assert d.pending
    e0 = d.event()
    d.synchronize()
    e1 = d.event()
    assert not d.pending and d.elapsed_ms(e0, e1) >= 0
    d.destroy_event(e0)
    d.destroy_event(e1)
    d.to_host(b, p)
    assert (b == a + 1).all()
    d.free(p)
    with pytest.raises(device.DeviceMemoryError):
        d.alloc(1 << 50)


def test_deferred_host_driver_runs_its_queue_at_synchronize():
    """HostDriver(deferred=True): uploads are the bytes at upload time, run in order with launches and events at
    synchronize(); a synchronous copy synchronizes first; frees of memory queued work may use wait their turn."""
    d = device.HostDriver(deferred=True)
    assert d.asynchronous and not d.pending
    p = d.alloc(64)
    a = np.arange(8, dtype=np.int64)
    d.upload(p, a)
    a[:] = -1  # after the upload: not what the device gets
    e0 = d.event()
    d.prepare_upload(p + 32, np.full(4, 7, np.int64))()
    e1 = d.event()
    raw = np.ctypeslib.as_array((ctypes.c_int64 * 8).from_address(p))
    assert d.pending and (raw == 0).all()  # nothing ran yet
    d.free(p)
    assert p in d._blocks  # queued: the copies before it still write there
    assert d.elapsed_ms(e0, e1) >= 0 and not d.pending  # reading an event's time ran the queue
    assert p not in d._blocks
    q = d.alloc(64)
    d.upload(q, np.arange(8, dtype=np.int64))
    b = np.zeros(8, np.int64)
    d.to_host(b, q)
    assert (b == np.arange(8)).all()


def test_host_driver_runs_a_kernels_launch_sequence(monkeypatch):
    """The flow the CUDA runtime will follow: a kernel's segments loaded as a module, its context buffer with
    the argument words, each Launch run with its grid (or a saturating one) and block, errors read back."""
    import simgrad as ti
    from simgrad.codegen import nvptx
    from simgrad.compiler.driver import compile_kernel
    from simgrad.lang.program import get_program
    from simgrad.runtime import abi

    monkeypatch.delenv("TI_ARCH", raising=False)  # the kernel's CPU launch gives the reference and the context
    ti.init(arch=ti.cpu)

    @ti.kernel
    def k(a: ti.f32, x: ti.types.ndarray(dtype=ti.f32, ndim=1), s: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        b = a * 2.0
        for i in range(x.shape[0]):
            x[i] = x[i] * b
        for i in range(x.shape[0]):
            s[0] += x[i]

    prog = get_program()
    x, s = np.arange(1000, dtype=np.float32), np.zeros(1, np.float32)
    ck = compile_kernel(k, prog, (1.5, x.copy(), s.copy()))
    cg = nvptx.GpuCodegen(ck.ir, "hd", sim=True)
    text = cg.generate()
    names = [ln.symbol for ln in cg.launches]
    addrs = prog.jit.code.link(prog.jit.object_for(text), names)
    d = device.HostDriver()
    fns = d.load_module(addrs, names)
    ck.launch(1.5, x, s)  # fills the launcher's context words for these arrays (and computes the CPU result)
    x_cpu, s_cpu = x.copy(), s.copy()
    x[:] = np.arange(1000, dtype=np.float32)
    s[:] = 0
    ctx = np.concatenate([ck.launcher.buf, np.zeros(cg.scratch_slots + 1, np.int64)])
    err = np.zeros(abi.ERR_WORDS, np.int64)
    ctx[abi.CTX_ERR] = err.ctypes.data
    for ln in cg.launches:
        d.launch(fns[ln.symbol], ln.grid or device.saturating_grid(d, ln.block), ln.block, ctx.ctypes.data)
    d.synchronize()
    assert err[0] == 0
    np.testing.assert_array_equal(x, x_cpu)
    np.testing.assert_allclose(s, s_cpu, rtol=1e-5)
