"""Field memory lies outside Python's heap (runtime/memory.py): a write just past a field's end, which
Taichi programs get away with (issue 21: differential_evolution.py writes best_fit[max_iter] and
all_pop[max_iter, ...]), must not corrupt malloc's bookkeeping (the process died later in the garbage
collector: SIGSEGV / 'double free or corruption'). Run in a child process, since failing is a crash."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent("""
    import gc
    import simgrad as ti

    ti.init(arch=ti.cpu)
    hist = ti.field(ti.f32, shape=(50, 20, 2))
    best = ti.field(ti.f32, shape=50)

    @ti.kernel
    def run(n: ti.i32):
        for _ in range(1):
            for t in range(1, n + 1):  # t == n is one row past the end, as in the example
                best[t] = 1.0
                for i, j in ti.ndrange(20, 2):
                    hist[t, i, j] = 2.0

    for _ in range(20):
        run(50)
        junk = [bytearray(100) for _ in range(2000)]
        gc.collect()
    print("DONE", float(best.to_numpy()[1:].sum()))
""")


def test_write_just_past_a_field_does_not_corrupt_the_heap(tmp_path):
    script = tmp_path / "overrun.py"
    script.write_text(SCRIPT)
    env = dict(os.environ, SIMGRAD_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, (out.returncode, out.stderr[-2000:])
    assert "DONE" in out.stdout


def test_trees_are_zeroed_aligned_and_do_not_overlap():
    import numpy as np

    import simgrad as ti
    from simgrad.lang.program import get_program

    fields = [ti.field(ti.f64, shape=n) for n in (1, 7, 1000, 3 << 20)]  # the last needs its own chunk
    for f in fields:
        f.fill(0)  # materialises
    views = [f.to_numpy() for f in fields]
    assert all(not v.any() for v in views)
    for k, f in enumerate(fields):
        f.fill(float(k + 1))
    for k, f in enumerate(fields):
        assert np.all(f.to_numpy() == k + 1)
    addrs = sorted((b.ctypes.data, b.nbytes) for b in get_program().memory._buffers.values())
    assert all(a % 64 == 0 for a, _ in addrs)
    assert all(a + n <= b for (a, n), (b, _) in zip(addrs, addrs[1:]))


def _vma_of(address: int) -> tuple[str, str]:
    """(permissions, VmFlags) of the mapping of this process that holds `address`."""
    perms, inside = "", False
    with open("/proc/self/smaps") as f:
        for line in f:
            head = line.split()
            if "-" in head[0] and len(head) >= 5 and all(c in "0123456789abcdef-" for c in head[0]):
                lo, hi = (int(x, 16) for x in head[0].split("-"))
                inside, perms = lo <= address < hi, head[1]
            elif inside and line.startswith("VmFlags:"):
                return perms, line
    raise AssertionError("no mapping holds the field")


def test_large_fields_are_private_memory_advised_for_huge_pages():
    """Fields moved from numpy's allocations (which ask for transparent huge pages) to our own mappings: a
    shared mapping (Python's mmap default) is shmem, which gets no huge pages, and a 10M-element saxpy ran at
    half its bandwidth. The mapping must be private and carry MADV_HUGEPAGE ('hg' in VmFlags)."""
    if not os.path.exists("/proc/self/smaps"):
        import pytest

        pytest.skip("needs Linux /proc/self/smaps")
    import simgrad as ti

    ti.init(arch=ti.cpu)
    x = ti.field(ti.f32, shape=4 << 20)
    x.fill(1.0)
    from simgrad.lang.program import get_program

    perms, flags = _vma_of(get_program().memory.roots[0])
    assert perms.endswith("p"), perms
    assert " hg" in flags, flags
