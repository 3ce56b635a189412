"""Differential fuzzing with programs of real shapes (tests/fuzz/shapes.py), CI budget: early-returning
ti.func/real_func, break/continue nests, run-time indexed local vectors/matrices, dataclasses, ndarrays,
sparse SNodes with struct-for, dynamic lists, atomics on locals/fields/ndarrays, selects of loads. Forward
programs against the Python/numpy reference of the same text; gradient programs against central finite
differences and forward mode against reverse. The mutation check plants bugs in the reference and shows
the campaign catches each one (so a quiet campaign means something)."""

from __future__ import annotations

import os
import sys

import pytest
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st

sys.path.insert(0, os.path.dirname(__file__))
import gen  # noqa: E402
import shapes  # noqa: E402

N = int(os.environ.get("SIMGRAD_FUZZ_EXAMPLES", "0"))


def _settings(default: int):
    return settings(max_examples=N or default, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@_settings(12)
@given(seed=st.integers(0, 2**31 - 1), size=st.integers(1, 8))
def test_shaped_programs_match_the_reference(tmp_path, seed, size):
    shapes.run_forward(seed, size, tmp_path)


@_settings(8)
@given(seed=st.integers(0, 2**31 - 1), size=st.integers(1, 5))
def test_shaped_gradients_match_finite_differences(tmp_path, seed, size):
    try:
        shapes.run_gradient(seed, size, tmp_path)
    except gen.Inconclusive:
        reject()


@_settings(8)
@given(seed=st.integers(0, 2**31 - 1), size=st.integers(1, 5))
def test_shaped_forward_mode_equals_reverse_mode(tmp_path, seed, size):
    shapes.run_forward_mode(seed, size, tmp_path)


# the first seed (size 3 + seed % 6) whose program each mutant makes disagree, tried first to keep CI short
FIRST_CATCH = {"atomic_add_as_sub": 5, "atomic_max_as_min": 3, "atomic_returns_new": 5, "break_to_continue": 18,
               "early_return_ignored": 1, "loop_bound_off_by_one": 0, "ndrange_lower_bound_0": 3,
               "select_negated": 0, "static_loop_off_by_one": 2, "struct_for_visits_inactive": 0}


@pytest.mark.parametrize("mutant", sorted(shapes.MUTANTS))
def test_a_bug_planted_in_the_reference_is_caught(tmp_path, mutant):
    """A program that the mutant changes and that it makes disagree is found within 20 programs containing
    its construct (seeds 0, 1, ..., the recorded one first): the construct is generated, reaches an output,
    and the comparison sees it."""
    tried = 0
    for seed in [FIRST_CATCH.get(mutant, 0), *range(400)]:
        size = 3 + seed % 6
        _, ref = shapes.forward_case(seed, size)
        if shapes.MUTANTS[mutant](ref) == ref:
            continue  # the program has no such construct
        tried += 1
        try:
            shapes.run_forward(seed, size, tmp_path, mutant=mutant)
        except AssertionError:
            return
        assert tried < 20, f"mutant {mutant} survived {tried} programs that contain its construct"
    pytest.fail(f"mutant {mutant}: no program among 400 seeds has its construct")
