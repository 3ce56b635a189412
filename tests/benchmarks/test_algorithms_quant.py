"""benchmarks/algorithms_quant.py in its tiny size, simgrad and numpy only: every case runs in its child process
and passes its own check against numpy (no timings asserted), and those checks do catch a wrong result."""

import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "benchmarks", "algorithms_quant.py")
spec = importlib.util.spec_from_file_location("algorithms_quant", SCRIPT)
aq = importlib.util.module_from_spec(spec)
spec.loader.exec_module(aq)


def test_tiny_run_simgrad_and_numpy():
    proc = subprocess.run([sys.executable, SCRIPT, "--tiny", "--runs", "1", "--frameworks", "simgrad,numpy",
                           "--markdown"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = {line.split(" | ")[0].lstrip("| "): line.split(" | ")[1:] for line in proc.stdout.splitlines()
            if line.startswith("| ") and not line.startswith("| case")}
    for label, _case, _metric in aq.ROWS:
        assert rows[label][0] != "-", (label, proc.stdout)  # simgrad gave a number
    for label in ("parallel_sort 10M i32 keys (ms)", "PrefixSumExecutor 100M i32 (ms)"):
        float(rows[label][2])  # numpy too
    # the layouts of quant.md, in bytes (Taichi 1.7.4 reports the same: see benchmarks/RESULTS.md)
    assert [rows[label][0] for label, case, _ in aq.ROWS if case == "quant_bytes"] == ["4", "4", "8", "16", "4"]
    assert rows["quantized MPM particle (bytes)"][0] == "24" and rows["f32 MPM particle (bytes)"][0] == "36"


class _NoSort:
    """A stand-in framework whose parallel_sort leaves the keys as they are."""

    i32 = "i32"

    class algorithms:
        @staticmethod
        def parallel_sort(keys, values=None):
            pass

    class _Field:
        def __init__(self, n):
            self.a = np.zeros(n, np.int32)

        def from_numpy(self, a):
            self.a = a.copy()

        def to_numpy(self):
            return self.a.copy()

    @classmethod
    def field(cls, dtype, n):
        return cls._Field(n)

    @staticmethod
    def sync():
        pass


def test_sort_check_catches_an_unsorted_result():
    with pytest.raises(AssertionError, match="np.sort"):
        aq.case_sort_keys(_NoSort, np, aq.TINY)
