"""ti.init / ti.reset cycles release what the dropped program held: its kernels' native code (an MCJIT
engine per program, closed on reset), its fields' memory, its launchers. Measured in a fresh process as the
resident set size over 1,000 cycles, each compiling (a kernel-cache hit after the first) and launching a
kernel. Before the per-program code space each cycle kept ~10 KB."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent("""
    import gc, os, sys
    import simgrad as ti

    def rss_kb():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024

    cache = sys.argv[1]
    samples = []
    for c in range(1000):
        ti.init(arch=ti.cpu, offline_cache_file_path=cache)
        x = ti.field(ti.f32, 64)

        @ti.kernel
        def k(a: ti.f32):
            for i in x:
                x[i] = a * i

        k(2.0)
        assert x[3] == 6.0
        ti.reset()
        if c in (100, 999):
            gc.collect()
            samples.append(rss_kb())
    print("GROWTH_KB", samples[1] - samples[0])
""")


def test_rss_flat_over_1000_init_reset_cycles(tmp_path):
    env = dict(os.environ)
    env.pop("SIMGRAD_DEBUG", None)
    script = tmp_path / "cycles.py"  # kernels need their source in a file
    script.write_text(SCRIPT)
    out = subprocess.run([sys.executable, str(script), str(tmp_path / "cache")], capture_output=True, text=True,
                         timeout=600, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    growth = int(out.stdout.split("GROWTH_KB")[1])
    assert growth < 1500, f"RSS grew by {growth} KB over 900 init/reset cycles"
