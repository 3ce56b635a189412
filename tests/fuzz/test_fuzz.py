"""Property-based differential fuzzing, CI budget: random typed kernels (integer wrap-around, Python // and
%, f32 rounding, casts, select, if/else, static and dynamic range-for, while/break, atomics) against a
Python/numpy reference of the same program text, and random differentiable f64 kernels (two kernels on a
Tape, ti.func, serial loops, branches) against central finite differences. Hypothesis draws a seed and a
size and shrinks both; a failure prints the whole program. The long run is benchmarks/fuzz_long.py
(docs/FUZZING.md)."""

from __future__ import annotations

import os
import sys

from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st

sys.path.insert(0, os.path.dirname(__file__))
import gen  # noqa: E402

SETTINGS = settings(max_examples=int(os.environ.get("SIMGRAD_FUZZ_EXAMPLES", "25")), deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
                    derandomize=True)


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1), size=st.integers(1, 8))
def test_random_kernels_match_the_reference(tmp_path, seed, size):
    gen.run_forward(seed, size, tmp_path)


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1), size=st.integers(1, 5))
def test_random_gradients_match_finite_differences(tmp_path, seed, size):
    try:
        gen.run_gradient(seed, size, tmp_path)
    except gen.Inconclusive:
        reject()  # finite differences cannot judge this program (they disagree with each other)


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1), size=st.integers(1, 5))
def test_random_forward_mode_equals_reverse_mode(tmp_path, seed, size):
    gen.run_forward_mode(seed, size, tmp_path)
