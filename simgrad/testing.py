"""Gradient checking for users and tests: reverse-mode gradients against central finite differences.

`check_grads(forward, inputs, outputs)` runs `forward()` (which must recompute `outputs` from `inputs`
from scratch each time) under a Tape, seeds each output's gradient with random weights w, and compares
the directional derivative along a random direction d of the inputs:

    AD = sum_k <grad_k, d_k>          FD = (L(x + eps d) - L(x - eps d)) / (2 eps),  L = sum <w, outputs>

and requires |AD - FD| <= atol + rtol * |FD| (the inner-product identity: one comparison per direction,
however many inputs there are). Use float64 fields for tight tolerances.

`check_program_grads(run, loss, params)` checks a whole program the same way (`run()` launches its kernels
and computes the 0-d field `loss` under a Tape) and, when the program's gradient disagrees, finds the
first launch to blame: it replays the recorded launches from a snapshot of all memory before each one and
checks each launch's adjoint alone with the inner-product identity over the whole state,
<u, K'(S) v> = <K'(S)^T u, v>, raising a GradientError that names the kernel (or @ti.ad.grad_replaced unit),
its file:line, the launch and its arguments. When every launch agrees it says the Tape misses something
(a Python-scope write between launches, a no_grad kernel, an input overwritten before backward).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import GradientError, Loc
from simgrad.lang import ad_hooks
from simgrad.lang.field import Field, ScalarField
from simgrad.lang.tape import Tape, _restore_memory, _save_memory


def _loss(outputs, weights) -> float:
    return float(sum(np.sum(o.to_numpy().astype(np.float64) * w) for o, w in zip(outputs, weights)))


def check_grads(forward, inputs, outputs, *, eps: float = 1e-6, rtol: float = 1e-5, atol: float = 1e-9,
                directions: int = 2, seed: int = 0, weights=None):
    """Assert that reverse-mode gradients of `outputs` w.r.t. `inputs` match finite differences.

    Returns the list of (AD, FD) pairs, one per random direction."""
    rng = np.random.default_rng(seed)
    if weights is None:
        weights = [rng.standard_normal(o.to_numpy().shape) if o.shape or hasattr(o, "n") else
                   np.array(rng.standard_normal()) for o in outputs]
    base = [x.to_numpy().astype(np.float64) for x in inputs]

    tape = Tape(loss=None, clear_gradients=True)
    with tape:
        forward()
    for o, w in zip(outputs, weights):
        o.grad.from_numpy(np.asarray(w, dtype=o.dtype.np).reshape(o.grad.to_numpy().shape))
    tape.grad()
    grads = [x.grad.to_numpy().astype(np.float64) for x in inputs]

    results = []
    try:
        for _ in range(directions):
            d = [rng.standard_normal(b.shape) for b in base]
            ad = float(sum(np.sum(g * dk) for g, dk in zip(grads, d)))
            vals = []
            for sign in (1.0, -1.0):
                for x, b, dk in zip(inputs, base, d):
                    x.from_numpy((b + sign * eps * dk).astype(x.dtype.np))
                forward()
                vals.append(_loss(outputs, weights))
            fd = (vals[0] - vals[1]) / (2 * eps)
            results.append((ad, fd))
            if not abs(ad - fd) <= atol + rtol * abs(fd):
                raise AssertionError(f"gradient check failed: AD {ad!r} vs finite differences {fd!r} "
                                     f"(|diff| {abs(ad - fd):.3e} > atol {atol} + rtol {rtol} * |FD|)")
    finally:
        for x, b in zip(inputs, base):
            x.from_numpy(b.astype(x.dtype.np))
    return results


# -- whole programs ------------------------------------------------------------------------------------
@dataclass
class ProgramGradReport:
    """What check_program_grads found when the program's gradient agrees: one (AD, FD) pair per direction,
    the step each pair used, and how many launches the Tape recorded."""

    pairs: list[tuple[float, float]]
    steps: list[float]
    launches: int
    names: list[str] = field(default_factory=list)  # the recorded launches, in order

    def __iter__(self):
        return iter(self.pairs)

    def __len__(self) -> int:
        return len(self.pairs)


class _Recorder:
    """Sits in front of the Tape's recorder: keeps every launch in order (the Tape drops @ti.ad.no_grad
    kernels, which the replay must still run) and passes each on. `insert` is what a grad_replaced unit
    calls on the recorder's owner."""

    def __init__(self, tape: Tape):
        self.tape = tape
        self.launches: list[tuple[Any, tuple]] = []

    def record(self, kernel, args) -> None:
        self.launches.append((kernel, args))
        self.tape._record(kernel, args)

    def insert(self, fn, args) -> None:
        self.launches.append((fn, args))
        self.tape.insert(fn, args)


def _state_fields() -> list[ScalarField]:
    """Every placed float scalar field (vector/matrix components included) that has a placed gradient:
    the state a launch's adjoint maps."""
    from simgrad.lang.program import get_program

    prog = get_program()
    prog.materialize_all()
    out = []
    for tree in prog.trees:
        for node in tree.root._walk():
            f = getattr(node, "field", None)
            if node.kind != "place" or not isinstance(f, ScalarField) or not f.is_primal or f.is_dual:
                continue
            g = f.grad
            if f.dtype.is_float and isinstance(g, ScalarField) and g.snode is not None:
                out.append(f)
    return out


def _defaults(fields: list, eps, rtol, atol) -> tuple[list[float], float, float]:
    precise = all(f.dtype is dt.f64 for f in fields)
    steps = [eps] if eps is not None else ([1e-6, 1e-5, 1e-7] if precise else [1e-3, 3e-3, 3e-4])
    return steps, (1e-5 if precise else 1e-2) if rtol is None else rtol, \
        (1e-8 if precise else 1e-4) if atol is None else atol


def _agree(ad: float, fd: float, scale: float, rtol: float, atol: float) -> bool:
    return abs(ad - fd) <= atol + rtol * max(abs(ad), abs(fd), scale)


def _forward(fn, args) -> None:
    outer, ad_hooks.recorder = ad_hooks.recorder, None
    try:
        fn(*args)
    finally:
        ad_hooks.recorder = outer


def _python_function(fn):
    return getattr(fn, "func", None) or getattr(fn, "fn", None) or fn


def _where(fn) -> Loc | None:
    """The file and `def` line of a kernel, grad_replaced unit or plain function."""
    f = inspect.unwrap(_python_function(fn))
    code = getattr(f, "__code__", None)
    if code is None:
        return None
    line = code.co_firstlineno
    try:
        lines, start = inspect.getsourcelines(f)
        for k, text in enumerate(lines):  # past the decorators
            if text.lstrip().startswith(("def ", "async def ")):
                line = start + k
                break
    except (OSError, TypeError):
        pass
    return Loc(code.co_filename, line)


def _name(fn) -> str:
    return getattr(fn, "name", None) or getattr(_python_function(fn), "__qualname__", None) or repr(fn)


def _describe(a) -> str:
    if isinstance(a, Field):
        return f"field {a.name}"
    if isinstance(a, (bool, int, float, str, type(None), np.generic)):
        return repr(a)
    name = getattr(a, "name", None)
    return f"{type(a).__name__} {name}" if isinstance(name, str) else type(a).__name__


def _unit(fn) -> str:
    """`kernel step (file:line)` or `grad_replaced unit f (file:line) with gradient g (file:line)`."""
    loc = _where(fn)
    if hasattr(fn, "func"):
        return f"kernel {_name(fn)} ({loc})"
    text = f"@ti.ad.grad_replaced unit {_name(fn)} ({loc})"
    g = getattr(fn, "grad", None)
    if g is not None:
        text += f" with gradient {_name(g)} ({_where(g)})"
    return text


@dataclass
class _LaunchCheck:
    ad: float
    fd: float
    step: float
    ok: bool
    fields: list[str]  # on failure: the state fields whose terms disagree


def _launch_fd(fn, args, state: list, fields: list[ScalarField], x0: list, v: list, u: list, h: float,
               only: int | None = None) -> tuple[float, float]:
    """<u, (dK(S + h v) - dK(S - h v)) / 2h> with dK(X) = K(X) - X, the change the launch makes (so a field
    it leaves alone contributes exactly 0); with `only`, v perturbs that field alone. Also the sum of the
    absolute terms (the scale of the sum)."""
    deltas = []
    for sign in (1.0, -1.0):
        _restore_memory(state)
        for k, (f, x, vk) in enumerate(zip(fields, x0, v)):
            if only is None or k == only:
                f.from_numpy((x + sign * h * vk).astype(f.dtype.np))
        inputs = [f.to_numpy().astype(np.float64) for f in fields]
        _forward(fn, args)
        deltas.append([f.to_numpy().astype(np.float64) - i for f, i in zip(fields, inputs)])
    terms = [uk * (p - m) / (2 * h) for uk, p, m in zip(u, deltas[0], deltas[1])]
    return float(sum(np.sum(t) for t in terms)), float(sum(np.sum(np.abs(t)) for t in terms))


def _check_launch(fn, args, state: list, fields: list[ScalarField], steps: list[float], rtol: float,
                  atol: float, rng) -> _LaunchCheck:
    """The adjoint of one launch from state S against finite differences of that launch alone: random v
    over the primal values and u over the gradients of `fields`; restore S, run forward, set every gradient
    to u, run the adjoint: the gradients then hold K'^T u (a store's adjoint consumes the gradient of what it
    overwrote). <K'^T u - u, v> must equal <u, (dK(S + h v) - dK(S - h v)) / 2h>."""
    _restore_memory(state)
    x0 = [f.to_numpy().astype(np.float64) for f in fields]
    v = [rng.standard_normal(x.shape) for x in x0]
    u = []
    _forward(fn, args)
    for f, x in zip(fields, x0):
        g = f.grad
        assert isinstance(g, ScalarField)
        g.from_numpy(rng.standard_normal(x.shape).astype(g.dtype.np))
        u.append(g.to_numpy().astype(np.float64))  # as stored
    fn.grad(*args)
    back = [f.grad.to_numpy().astype(np.float64) for f in fields]  # type: ignore[union-attr]
    ad_terms = [(b - uk) * vk for b, uk, vk in zip(back, u, v)]
    ad = float(sum(np.sum(t) for t in ad_terms))
    ad_scale = float(sum(np.sum(np.abs(t)) for t in ad_terms))
    best: tuple[float, float, float] | None = None
    for h in steps:
        fd, fd_scale = _launch_fd(fn, args, state, fields, x0, v, u, h)
        if _agree(ad, fd, max(ad_scale, fd_scale), rtol, atol):
            return _LaunchCheck(ad, fd, h, True, [])
        if best is None or abs(ad - fd) < abs(ad - best[0]):
            best = (fd, h, fd_scale)
    assert best is not None
    fd, h, _ = best
    # which state fields carry the disagreement: perturb one field at a time
    bad = []
    for k, f in enumerate(fields):
        fd_k, scale_k = _launch_fd(fn, args, state, fields, x0, v, u, h, only=k)
        ad_k = float(np.sum(ad_terms[k]))
        if not _agree(ad_k, fd_k, max(float(np.sum(np.abs(ad_terms[k]))), scale_k), rtol, atol):
            bad.append(f"{f.name}.grad (AD {ad_k:.10g}, FD {fd_k:.10g})")
    return _LaunchCheck(ad, fd, h, False, bad)


def _program_fd(run, loss, params: list, base: list, d: list, h: float, before: list) -> float:
    vals = []
    for sign in (1.0, -1.0):
        _restore_memory(before)
        for p, b, dk in zip(params, base, d):
            p.from_numpy((b + sign * h * dk).astype(p.dtype.np))
        outer, ad_hooks.recorder = ad_hooks.recorder, None
        try:
            run()
        finally:
            ad_hooks.recorder = outer
        vals.append(float(loss.to_numpy()))
    return (vals[0] - vals[1]) / (2 * h)


def check_program_grads(run, loss, params, *, directions: int = 3, eps: float | None = None,
                        rtol: float | None = None, atol: float | None = None, seed: int = 0) -> ProgramGradReport:
    """Check the Tape gradients of a whole program against central finite differences, and on disagreement
    name the first launch whose adjoint is wrong.

    `run()` launches the forward kernels and computes the 0-d field `loss` (needs_grad) from the current
    field values; it is called under `ti.ad.Tape(loss=loss)` once and then again (outside the Tape) for each
    finite difference, each time from the memory the Tape started from. `params` are the fields (with
    gradients) whose gradients are checked: `sum_k <params_k.grad, d_k>` against the central difference of
    the loss along random directions d, at a few steps (`eps`; by default chosen from the dtype, as are
    rtol and atol: f64 1e-5/1e-8, else 1e-2/1e-4). One step in agreement passes a direction.

    On disagreement the recorded launches are replayed from the Tape's starting memory, each checked alone
    from a snapshot of all memory before it (see `_check_launch`): kernels through `kernel.grad`,
    @ti.ad.grad_replaced units through their @ti.ad.grad_for function; @ti.ad.no_grad kernels run but are
    not checked. A GradientError names the first launch that disagrees (kernel, file:line, launch index,
    arguments, the two numbers and the fields involved), or says that every launch agrees and the Tape
    misses something. Memory (values and gradients) is left as the Tape's backward pass left it."""
    if isinstance(params, Field):
        params = [params]
    params = list(params)
    if not isinstance(loss, ScalarField) or loss.shape != ():
        raise GradientError("check_program_grads: the loss must be a 0-d scalar field (ti.field(dtype, shape=()))")
    for p in params:
        if not isinstance(p, Field) or p.grad is None:
            raise GradientError(f"check_program_grads: parameter {getattr(p, 'name', p)!r} is not a field "
                                "with a gradient (needs_grad=True)")
    steps, rtol_, atol_ = _defaults([loss, *params], eps, rtol, atol)
    rng = np.random.default_rng(seed)

    tape = Tape(loss=loss)
    rec = _Recorder(tape)
    with tape:
        before = _save_memory()  # after the Tape zeroed the loss and the gradients
        ad_hooks.recorder = rec.record
        run()
    after = _save_memory()
    try:
        grads = [p.grad.to_numpy().astype(np.float64) for p in params]
        base = [p.to_numpy().astype(np.float64) for p in params]
        pairs, used = [], []
        failed: tuple[float, float, float] | None = None
        for _ in range(directions):
            d = [rng.standard_normal(b.shape) for b in base]
            terms = [g * dk for g, dk in zip(grads, d)]
            ad = float(sum(np.sum(t) for t in terms))
            scale = float(sum(np.sum(np.abs(t)) for t in terms))
            best: tuple[float, float] | None = None
            for h in steps:
                fd = _program_fd(run, loss, params, base, d, h, before)
                if best is None or abs(ad - fd) < abs(ad - best[0]):
                    best = (fd, h)
                if _agree(ad, fd, scale, rtol_, atol_):
                    break
            assert best is not None
            pairs.append((ad, best[0]))
            used.append(best[1])
            if not _agree(ad, best[0], scale, rtol_, atol_):
                failed = (ad, best[0], best[1])
                break
        launches = rec.launches
        if failed is None:
            return ProgramGradReport(pairs, used, len(launches), [_name(fn) for fn, _ in launches])
        _blame(launches, before, steps, rtol_, atol_, rng, failed)
        raise AssertionError("unreachable")  # _blame always raises
    finally:
        _restore_memory(after)


def _blame(launches: list, before: list, steps: list[float], rtol: float, atol: float, rng,
           failed: tuple[float, float, float]) -> None:
    ad, fd, h = failed
    fields = _state_fields()
    _restore_memory(before)
    checked = 0
    for k, (fn, args) in enumerate(launches):
        state = _save_memory()
        if not getattr(fn, "_no_grad", False) and getattr(fn, "grad", None) is not None:
            r = _check_launch(fn, args, state, fields, steps, rtol, atol, rng)
            checked += 1
            if not r.ok:
                shown = ", ".join(_describe(a) for a in args)
                hint = ""
                if not hasattr(fn, "func"):
                    hint = ("\nA custom gradient must map the gradients as kernel.grad does: add the "
                            "derivative to each input's gradient, and leave the gradient of an element the "
                            "forward overwrote at zero.")
                raise GradientError(
                    f"the adjoint of launch #{k} of {len(launches)}, {_unit(fn)}, arguments ({shown}), "
                    f"disagrees with finite differences of that launch alone: from random state "
                    f"perturbations v and gradients u, the adjoint gives <K^T u - u, v> = {r.ad:.10g} but "
                    f"central differences give <u, K v - v> = {r.fd:.10g} (step {r.step:g}); the gradients "
                    f"that disagree: {', '.join(r.fields) or 'no single field alone'}.\nThe whole program: "
                    f"AD {ad:.10g} vs FD {fd:.10g} (step {h:g}).{hint}", _where(fn))
        _restore_memory(state)
        _forward(fn, args)
    raise GradientError(
        f"the program's gradient disagrees with finite differences (AD {ad:.10g} vs FD {fd:.10g}, step {h:g}), "
        f"but each of the {checked} recorded launches with an adjoint (of {len(launches)}) agrees with finite "
        "differences of that launch alone: the Tape misses a dependence between launches. Look for a "
        "Python-scope write between launches (from_numpy, x[i] = ..., fill outside a kernel), a "
        "@ti.ad.no_grad kernel or a field without gradient that carries a dependence, or a kernel input "
        "overwritten before backward (the global data access rule; Tape(validation=True) checks it).")
