"""SIMGRAD_DEBUG dumps what it promises whether or not the kernel or its object is already cached
(runtime/jit.py debug_level): 1 pass names, 2 IR after each pass, 3 optimised LLVM IR, 4 assembly."""

import simgrad as ti
from simgrad.runtime.jit import get_jit


def _compile_and_run(tag: float):
    x = ti.field(ti.f32, shape=4)

    @ti.kernel
    def debug_dump_kernel():
        for i in x:
            x[i] = i * tag

    debug_dump_kernel()
    assert x.to_numpy().tolist() == [i * tag for i in range(4)]


def test_levels_3_and_4_print_on_object_cache_hits(monkeypatch, capsys):
    monkeypatch.setenv("SIMGRAD_DEBUG", "4")
    _compile_and_run(2.0)
    first = capsys.readouterr().out
    hits = get_jit().stats["cache_hits"]
    ti.init(arch=ti.cpu)  # a new program compiles again: the object now comes from the disk cache
    _compile_and_run(2.0)
    second = capsys.readouterr().out
    assert get_jit().stats["cache_hits"] > hits
    for out in (first, second):
        assert "[simgrad] debug_dump_kernel: parallel_strategy" in out  # level 1
        assert "range_for" in out  # level 2: the IR
        assert "define void @sg_kernel(ptr" in out and "_task1(" in out  # level 3: the LLVM IR
        assert "sg_kernel:\n" in out and "\t.section\t" in out  # level 4: the assembly


def test_debug_levels_bypass_a_kernel_cache_hit(monkeypatch, capsys):
    _compile_and_run(3.0)  # stored in the kernel cache, printing nothing
    assert capsys.readouterr().out == ""
    ti.init(arch=ti.cpu)
    monkeypatch.setenv("SIMGRAD_DEBUG", "1")
    _compile_and_run(3.0)
    out = capsys.readouterr().out
    assert "[simgrad] debug_dump_kernel: promote" in out and "hoist" in out
