"""Ctrl-C stops a running kernel within a second and raises KeyboardInterrupt: a native SIGINT handler sets
the cancel flag (then chains to Python's), while loops, long or unbounded serial for loops (every 2**16
iterations) and the pool's chunk loop look at it, and the
program stays usable. Run in a child process that signals itself."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import os, signal, sys, threading, time
    # a SIGINT ignored or blocked by the process that started this one is inherited across exec: undo that
    signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT])
    signal.signal(signal.SIGINT, signal.default_int_handler)
    import simgrad as ti

    ti.init(arch=ti.cpu, cpu_max_num_threads=int(sys.argv[2]))
    x = ti.field(ti.i64, 4)

    @ti.kernel
    def endless():
        for i in range(4):
            k = 0
            while k >= 0:  # never ends
                k = (k + 1) % 1000
                x[i] += 1

    @ti.kernel
    def serial_endless():
        k = 0
        while k >= 0:
            k = (k + 1) % 7

    @ti.kernel
    def huge(n: ti.i64):
        for i in range(n):  # ~hours of work in one parallel loop
            x[i % 4] += 1

    @ti.kernel
    def inner():
        for i in range(4):  # each element's time goes into a long serial loop
            for j in range(2000000000):
                x[i] = (x[i] * 31 + j) % 1000003

    @ti.kernel
    def count() -> ti.i32:
        s = 0
        for i in range(100):
            s += 1
        return s

    kernel = {"while": endless, "serial": serial_endless, "range": lambda: huge(10 ** 13),
              "inner": inner}[sys.argv[1]]
    threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
    t = time.perf_counter()
    try:
        kernel()
        print("RETURNED")
    except KeyboardInterrupt:
        print("INTERRUPTED", time.perf_counter() - t)
    print("AFTER", count())
""")


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("kind", ["while", "serial", "range", "inner"])
def test_ctrl_c_stops_a_running_kernel(tmp_path, kind, threads):
    script = tmp_path / "endless.py"
    script.write_text(SCRIPT)
    env = dict(os.environ, SIMGRAD_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, str(script), kind, str(threads)], capture_output=True, text=True,
                         timeout=60, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.split("\n")
    stopped = [ln for ln in lines if ln.startswith("INTERRUPTED")]
    assert stopped, out.stdout + out.stderr[-2000:]
    assert float(stopped[0].split()[1]) < 0.5 + 1.0  # within a second of the signal
    assert "AFTER 100" in lines  # the next launch is not reported as interrupted


COPIES = textwrap.dedent("""
    import os, signal, sys, threading
    signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT])
    signal.signal(signal.SIGINT, signal.default_int_handler)
    import numpy as np
    import simgrad as ti

    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    x = ti.field(ti.i64, 4)

    @ti.kernel
    def huge(n: ti.i64, h: ti.types.ndarray()):
        for i in range(n):  # per-thread copies of x and of h (many updates into 4 elements)
            x[i % 4] += 1
            h[i % 4] += 1

    h = np.zeros(4, np.int64)
    threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
    try:
        huge(10 ** 13, h)
    except KeyboardInterrupt:
        print("INTERRUPTED")
    x.fill(0)
    h[:] = 0
    huge(100_000, h)
    print("AFTER", [int(v) for v in x.to_numpy()], [int(v) for v in h])
""")


def test_a_scatter_interrupted_in_its_copies_leaves_none_of_its_partials_to_the_next_launch(tmp_path):
    """Ctrl-C while the variant over per-thread copies runs: the pool hands out no more chunks, so the final sum
    would not run and the copies, kept between launches, would add the interrupted launch's partials into the next
    one's results. The entry sums them on the calling thread instead (the copies end zero)."""
    script = tmp_path / "copies.py"
    script.write_text(COPIES)
    env = dict(os.environ, SIMGRAD_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "INTERRUPTED" in out.stdout, out.stdout + out.stderr[-2000:]
    assert "AFTER [25000, 25000, 25000, 25000] [25000, 25000, 25000, 25000]" in out.stdout, out.stdout
