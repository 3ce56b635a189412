"""ti.ad.checkpoint: differentiate a long simulation that advances its state in place, under a memory budget.

`ti.ad.checkpoint(step, n_steps, state=[x, v], budget=K)` inside `with ti.ad.Tape(loss=...)` runs `step(t)`
for t in range(n_steps) and puts one unit on the Tape. Forward keeps only the state before step 0 and after
the last step; backward rebuilds earlier states by recomputing from snapshots it places with the binomial
(Revolve) schedule: with K snapshots of the state, no step is recomputed more than t times where
C(K + t, t) >= n_steps (K = 10, n = 1000: 4). Each step's adjoint runs kernel by kernel, in reverse order, on
the state *before* that kernel (the step is replayed up to it), so a kernel may read and overwrite the same
element in place (autodiff/validate.py check_owned_in_place says which in-place updates are allowed).

After backward, `x.grad` for every state field is d loss / d (state before step 0); fields read by the steps
but not in `state` (parameters) have accumulated their gradients; the state holds its final values again.
Memory: K + 3 copies of the state (the budget, the initial and final state, the state before the step whose
adjoint is running). `step(t)` is run once per step in forward, and its kernel launches (with their
arguments) are recorded: backward replays those launches, so a step must do its work in kernels (what it does
in Python scope happens once, in forward). The snapshots of backward's first descent are taken during
forward, which saves one sweep of recomputation. Fields a step writes that are not in `state` must be
overwritten by the step before they are read (temporaries such as forces): they are recomputed, never saved.
"""

from __future__ import annotations

from contextlib import contextmanager
from math import comb

import numpy as np

from simgrad.errors import SimgradError, caller_loc
from simgrad.lang import ad_hooks


def _snapshot(state: list) -> list[np.ndarray]:
    return [f.to_numpy() for f in state]


def _restore(state: list, snap: list[np.ndarray]) -> None:
    for f, a in zip(state, snap):
        f.from_numpy(a)


@contextmanager
def _unrecorded():
    """Launches made inside are recorded by no Tape (backward's replays and adjoints)."""
    outer, ad_hooks.recorder = ad_hooks.recorder, None
    try:
        yield
    finally:
        ad_hooks.recorder = outer


def _reach(s: int, t: int) -> int:
    """How many steps s snapshots and t recomputations per step can reverse (Griewank's beta)."""
    return comb(s + t, t)


def _split(n: int, s: int) -> int:
    """Where to place the next snapshot in a range of n steps with s snapshots left (binomial schedule): far
    enough that the rest fits s - 1 snapshots with the same number of recomputations."""
    t = 0
    while _reach(s, t) < n:
        t += 1
    return max(1, min(n - 1, n - _reach(s - 1, t)))


class _Recorder:
    """Collects the kernel launches of one step (they also run)."""

    def __init__(self):
        self.launches: list = []
        self.__self__ = self  # what @ti.ad.grad_replaced units look for to insert themselves

    def __call__(self, kernel, args) -> None:
        if not getattr(kernel, "_no_grad", False):
            self.launches.append((kernel, args))

    def insert(self, fn, args) -> None:  # a @ti.ad.grad_replaced unit launched by the step
        self.launches.append((fn, args))


class Checkpoint:
    """The Tape entry of one ti.ad.checkpoint call; `grad()` is its backward."""

    def __init__(self, step, n_steps: int, state: list, budget: int):
        self.step, self.n, self.state, self.budget = step, n_steps, list(state), budget
        self.peak = 0  # most snapshots held at once (the budget is an upper bound), for reports and tests
        self.recomputed = 0  # steps run again in backward
        self._held = 0

    def _run(self, t: int) -> list:
        rec, outer = _Recorder(), ad_hooks.recorder
        ad_hooks.recorder = rec
        try:
            self.step(t)
        finally:
            ad_hooks.recorder = outer
        return rec.launches

    def forward(self) -> None:
        self.start = _snapshot(self.state)
        # the snapshots backward's first descent places (the schedule's right spine) are taken on the way
        # forward instead of recomputed: one sweep fewer, and never more than the budget held at once
        spine, t0, s = set(), 0, self.budget
        while self.n - t0 > 1 and s > 0:
            t0 += _split(self.n - t0, s)
            spine.add(t0)
            s -= 1
        self.pre: dict[int, list] = {}
        # each step's launches (kernels and their arguments) are kept: backward replays them without asking
        # the step again
        self.launches = []
        for t in range(self.n):
            self.launches.append(self._run(t))
            if t + 1 in spine:
                self.pre[t + 1] = _snapshot(self.state)
                self._hold(1)
        self.end = _snapshot(self.state)

    def grad(self, *_args) -> None:
        self._reverse(0, self.n, self.start, self.budget)
        _restore(self.state, self.end)

    def _replay(self, t: int) -> None:
        """Step t again, from its recorded launches."""
        with _unrecorded():
            for fn, args in self.launches[t]:
                fn(*args)

    def _hold(self, k: int) -> None:
        self._held += k
        self.peak = max(self.peak, self._held)

    def _reverse(self, t0: int, t1: int, snap: list, budget: int) -> None:
        """Adjoints of steps t0 .. t1 - 1 in reverse order, given the state before t0."""
        n = t1 - t0
        if n == 1:
            self._step_adjoint(t0, snap)
            return
        if budget == 0:  # no snapshot left: recompute from t0 for every step
            for t in range(t1 - 1, t0 - 1, -1):
                _restore(self.state, snap)
                for u in range(t0, t):
                    self._replay(u)
                    self.recomputed += 1
                self._step_adjoint(t, _snapshot(self.state))
            return
        m = _split(n, budget)
        mid = self.pre.pop(t0 + m, None)
        if mid is None:
            _restore(self.state, snap)
            for u in range(t0, t0 + m):
                self._replay(u)
                self.recomputed += 1
            mid = _snapshot(self.state)
            self._hold(1)
        self._reverse(t0 + m, t1, mid, budget - 1)
        del mid
        self._hold(-1)
        self._reverse(t0, t0 + m, snap, budget)

    def _step_adjoint(self, t: int, before: list) -> None:
        """The adjoint of step t, launch by launch in reverse, each on the state before that launch."""
        launches = self.launches[t]
        for j in range(len(launches) - 1, -1, -1):
            _restore(self.state, before)
            with _unrecorded():
                for fn, args in launches[:j]:
                    fn(*args)
                fn, args = launches[j]
                grad = getattr(fn, "grad", None)
                if grad is None:
                    raise SimgradError(f"step {t} launched {getattr(fn, '__name__', fn)!r}, which has no "
                                       "gradient")
                in_place = getattr(grad, "in_place", None)
                (in_place or grad)(*args)


def checkpoint(step, n_steps: int, state, budget: int = 10) -> Checkpoint:
    """Run `step(t)` for t in range(n_steps) inside a Tape, keeping at most `budget` snapshots of the `state`
    fields for backward (binomial schedule). Returns the Tape entry (its `peak` and `recomputed` report what
    backward used)."""
    tape = getattr(ad_hooks.recorder, "__self__", None)
    if tape is None or not hasattr(tape, "insert"):
        raise SimgradError("ti.ad.checkpoint must be called inside `with ti.ad.Tape(loss=...)`", caller_loc())
    if not isinstance(n_steps, int) or n_steps < 1:
        raise SimgradError(f"checkpoint: n_steps must be a positive int, got {n_steps!r}", caller_loc())
    if not isinstance(budget, int) or budget < 0:
        raise SimgradError(f"checkpoint: budget must be a non-negative int, got {budget!r}", caller_loc())
    state = list(state)
    if not state:
        raise SimgradError("checkpoint: state lists the fields each step advances in place", caller_loc())
    cp = Checkpoint(step, n_steps, state, budget)
    cp.forward()
    tape.insert(cp, ())
    return cp
