"""The pass pipeline: one readable function, one line per pass."""

from __future__ import annotations

import os
from collections.abc import Callable
from functools import partial

from simgrad.ir.nodes import Kernel
from simgrad.ir.printer import print_kernel


def _debug() -> int:
    from simgrad.debug import debug_level

    return debug_level()


def _verify_enabled() -> bool:
    """The verifier runs between passes in tests and debug runs (SIMGRAD_VERIFY=1 or SIMGRAD_DEBUG)."""
    return os.environ.get("SIMGRAD_VERIFY", "0") not in ("", "0") or _debug() > 0


def run_pipeline(kernel: Kernel, transform=None, debug: bool = False, fast_math: bool = False,
                 cache_sums: bool = True, lanes: int = 0, vector_bits: int = 0, fission: int = 0,
                 versions: bool = False) -> None:
    """`debug`: ti.init(debug=True), which every index is bounds-checked under (no paired atomics);
    `fast_math` lets serial-loop sums be reordered (passes/accumulate.py; `cache_sums`: Taichi's
    cache_loop_invariant_global_vars); `lanes` > 1: parallel loops of while loops run that many iterations in lock
    step (passes/lanes.py; the CPU's forward kernels), -1: as many as four `vector_bits` registers hold; `fission`:
    the same for parallel loops that scatter, split into the part before the scatters and the scatters
    (passes/fission.py; the CPU's kernels); `versions`: a copy of a parallel loop per value of a launch-wide
    component index (passes/unswitch.py; the CPU's kernels)."""
    from simgrad.passes import (
        accumulate,
        hoist,
        lower_access,
        parallel_strategy,
        promote,
        quant,
        reciprocal,
        simplify,
        verify,
    )
    from simgrad.passes import fission as split
    from simgrad.passes import lanes as simt
    from simgrad.passes import lanes_memory as simt_memory
    from simgrad.passes import store_select as stores
    from simgrad.passes import unswitch as per_value

    level = _debug()
    steps: list[tuple[str, Callable[[Kernel], object]]] = [
        ("promote", promote.promote),  # locals assigned once become their values
        ("simplify", simplify.simplify)]  # constant folding, algebraic identities, CSE, DCE
    if transform is not None:  # e.g. the reverse-mode adjoint, then a clean-up of what it produced
        steps += [(getattr(transform, "__name__", "transform"), transform), ("simplify", simplify.simplify)]
    if fast_math:  # a / c -> a * (1 / c), as taichi's fast_math
        steps.append(("reciprocal", reciprocal.reciprocal))
    # loop-invariant index arithmetic out of parallel loops, then merged where it became common
    steps.append(("hoist", lambda k: hoist.hoist(k) and simplify.simplify(k)))
    if versions:  # `v[i][k]` with k the same for the whole launch: a loop per value of k, one load or store each
        steps.append(("unswitch", lambda k: per_value.unswitch(k) and simplify.simplify(k)))
    steps.append(("store_select", stores.store_select))  # `if c: x[p] = v` after a store to x[p]: a select
    # quant fields: accesses become integer IR on their physical cells (compare-and-swap loops for writes)
    steps.append(("quant", quant.expand_quant))
    # how each parallel loop and atomic update runs (plain, per-thread sum, private copy, paired CAS, atomic)
    steps.append(("parallel_strategy", partial(parallel_strategy.parallel_strategy, debug=debug)))
    if fast_math:  # sums in serial loops in locals, reassociable: LLVM vectorises them as reductions
        steps.append(("accumulate", partial(accumulate.accumulate, cache_sums=cache_sums and not debug)))
    if lanes:  # while loops of local arithmetic in parallel loops: W iterations in lock step, vectorisable
        steps.append(("lanes", partial(simt.lanes, width=lanes, vector_bits=vector_bits)))
        # the loops it left whose lock-step part loads fields, stores own elements or counts (passes/lanes_memory.py)
        steps.append(("lanes_memory", partial(simt_memory.lanes_memory, width=lanes, vector_bits=vector_bits)))
    if fission:  # parallel loops with scatters: W iterations' pure part, then their scatters (vectorisable)
        steps.append(("fission", partial(split.fission, width=fission, vector_bits=vector_bits)))
    # element accesses become byte offsets in the IR, by SNode kind (debug: each index checked first)
    steps.append(("lower_access", partial(lower_access.lower_access, debug=debug)))
    if _verify_enabled():  # structural and type invariants before and after every pass
        steps = [("verify", verify.verify)] + [x for st in steps for x in (st, ("verify", verify.verify))]
    else:  # the frontend's output and the last pass's always (linear, cheap next to LLVM): invalid IR is a
        # located internal error, never LLVM's verifier or a silently wrong fold of an out-of-scope value
        steps = [("verify", verify.verify), *steps, ("verify", verify.verify)]
    if transform is not None and kernel.functions:
        _refuse_transform(kernel)
    for name, fn in steps:
        if level >= 1:
            print(f"[simgrad] {kernel.name}: {name}")
        fn(kernel)
        for func in kernel.functions:  # a real function's body: the same passes, never the transform
            if fn is not transform:
                fn(func)
        if level >= 2:
            print(print_kernel(kernel))


def _refuse_transform(kernel: Kernel) -> None:
    """Taichi compiles no gradient of a kernel that calls a real function; simgrad inlines the ones that do not
    recurse (so their gradients work) and refuses, at the call, a kernel that still calls one."""
    from simgrad.errors import SimgradSyntaxError
    from simgrad.ir.nodes import walk
    from simgrad.ir.ops import Op

    call = next(s for s in walk(kernel.body) if s.op is Op.CALL)
    raise SimgradSyntaxError("Real function in gradient kernels unsupported.", call.loc)
