# mypy: disable-error-code="valid-type"
"""ti.algorithms.parallel_sort: an in-place, stable LSD radix sort of a 1-D field or ndarray, with an optional
field or ndarray of values moved along, in simgrad kernels.

Taichi 1.7.4 runs Batcher's odd-even merge sort (log^2 n launches, O(n log^2 n) compare-and-swaps, not stable).
A radix sort is O(n) per 8-bit digit and stable, so it is one valid result of Taichi's sort (equal keys keep
their order; Taichi's may swap them), and the values end as numpy's stable argsort moves them. Each pass over
a digit is three kernels over blocks of the array: count the digits of each block (parallel over blocks),
turn the counts into every (digit, block)'s first output place (one serial scan, digit-major: that is what
makes it stable), scatter each block's elements to their places (parallel over blocks, in order within one).
A pass whose digit is the same in every key moves nothing and is skipped (f16 keys, small integers).

Keys are compared through an unsigned integer of the same order (`order_bits`): integers with the sign bit
flipped, floats by their bits with the negative ones inverted; -0.0 orders as 0.0 and every NaN after +inf,
as numpy sorts them (Taichi's comparison network leaves NaNs anywhere)."""

import simgrad as ti
from simgrad.algorithms.containers import Array1D, copy, not_on_a_tape, python_scope
from simgrad.errors import SimgradTypeError, SimgradValueError, caller_loc

RADIX = 256  # 8-bit digits
_BLOCK = 32768  # elements per block, at most _MAX_BLOCKS blocks
_MAX_BLOCKS = 256

# key dtype -> (width of its order bits, the unsigned type holding them)
_KEY_TYPES = {ti.u8: 8, ti.i8: 8, ti.u16: 16, ti.i16: 16, ti.u32: 32, ti.i32: 32, ti.f16: 32, ti.f32: 32,
              ti.u64: 64, ti.i64: 64, ti.f64: 64}


def order_bits(kdt):
    """A ti.func giving a key's unsigned integer of the same order (u32, u64 for 64-bit keys)."""
    if kdt in (ti.u8, ti.u16, ti.u32, ti.u64):
        wide = ti.u64 if kdt == ti.u64 else ti.u32

        @ti.func
        def bits(x):
            return ti.cast(x, wide)
    elif kdt in (ti.i8, ti.i16):
        bias = 1 << (_KEY_TYPES[kdt] - 1)

        @ti.func
        def bits(x):
            return ti.cast(ti.cast(x, ti.i32) + bias, ti.u32)
    elif kdt in (ti.i32, ti.i64):
        wide = ti.u64 if kdt == ti.i64 else ti.u32
        sign = 1 << (_KEY_TYPES[kdt] - 1)

        @ti.func
        def bits(x):
            return ti.bit_cast(x, wide) ^ wide(sign)
    else:
        real = ti.f64 if kdt == ti.f64 else ti.f32
        wide = ti.u64 if kdt == ti.f64 else ti.u32
        width = _KEY_TYPES[kdt]
        sign, top = 1 << (width - 1), (1 << width) - 1

        @ti.func
        def bits(x):
            y = ti.cast(x, real)  # f16 widens exactly
            u = ti.bit_cast(y, wide)
            r = ti.select(u >= wide(sign), ~u, u | wide(sign))
            r = ti.select(y == 0, wide(sign), r)  # -0.0 is 0.0
            return ti.select(y != y, wide(top), r)  # NaN last

    return bits


_KERNELS: dict = {}


def _kernels(kdt):
    """The count, scan and scatter kernels for keys of one dtype (made once per dtype)."""
    if kdt in _KERNELS:
        return _KERNELS[kdt]
    bits = order_bits(kdt)
    wide = ti.u64 if _KEY_TYPES[kdt] == 64 else ti.u32

    @ti.func
    def digit(x, shift):
        return ti.cast((bits(x) >> ti.cast(shift, wide)) & wide(RADIX - 1), ti.i32)

    @ti.kernel
    def count(keys: ti.types.ndarray(), n: ti.i32, nb: ti.i32, bs: ti.i32, shift: ti.i32,
              h: ti.types.ndarray()):
        ti.loop_config(block_dim=1)
        for b in range(nb):  # h[b * RADIX + d]: block b's keys with digit d (a block's counts are its own)
            for d in range(RADIX):
                h[b * RADIX + d] = 0
            for i in range(b * bs, ti.min(b * bs + bs, n)):
                k = b * RADIX + digit(keys[i], shift)
                h[k] = h[k] + 1

    @ti.kernel
    def places(h: ti.types.ndarray(), n: ti.i32, nb: ti.i32) -> ti.i32:
        trivial = 0
        run = 0
        ti.loop_config(serialize=True)
        for d in range(RADIX):  # digit-major: digit d's keys block by block, then digit d + 1's
            start = run
            for b in range(nb):
                c = h[b * RADIX + d]
                h[b * RADIX + d] = run
                run += c
            if run - start == n:
                trivial = 1
        return trivial

    @ti.kernel
    def scatter(src: ti.types.ndarray(), dst: ti.types.ndarray(), n: ti.i32, nb: ti.i32, bs: ti.i32,
                shift: ti.i32, h: ti.types.ndarray()):
        ti.loop_config(block_dim=1)
        for b in range(nb):
            for i in range(b * bs, ti.min(b * bs + bs, n)):
                x = src[i]
                k = b * RADIX + digit(x, shift)
                p = h[k]
                h[k] = p + 1
                dst[p] = x

    @ti.kernel
    def scatter_values(src: ti.types.ndarray(), dst: ti.types.ndarray(), vsrc: ti.types.ndarray(),
                       vdst: ti.types.ndarray(), n: ti.i32, nb: ti.i32, bs: ti.i32, shift: ti.i32,
                       h: ti.types.ndarray()):
        ti.loop_config(block_dim=1)
        for b in range(nb):
            for i in range(b * bs, ti.min(b * bs + bs, n)):
                x = src[i]
                k = b * RADIX + digit(x, shift)
                p = h[k]
                h[k] = p + 1
                dst[p] = x
                vdst[p] = vsrc[i]

    _KERNELS[kdt] = count, places, scatter, scatter_values
    return _KERNELS[kdt]


def parallel_sort(keys, values=None) -> None:
    """Sort the 1-D field or ndarray `keys` ascending in place; when given, `values` (a 1-D field or ndarray
    of scalars, vectors or matrices, at least as long as keys) is permuted with them. Stable."""
    python_scope("parallel_sort")
    k = Array1D(keys, "parallel_sort's keys")
    if k.entry_shape or k.dtype not in _KEY_TYPES:
        got = f"entries of shape {k.entry_shape}" if k.entry_shape else str(k.dtype)
        raise SimgradTypeError(f"parallel_sort's keys must be integers or floats (i8..i64, u8..u64, f16, f32, "
                               f"f64), got {got}", caller_loc())
    v = Array1D(values, "parallel_sort's values") if values is not None else None
    if v is not None and v.n < k.n:
        raise SimgradValueError(f"parallel_sort's values have {v.n} elements, fewer than the {k.n} keys",
                                caller_loc())
    if v is not None and v.obj is keys:
        v = None  # sorting a container as its own values
    not_on_a_tape("parallel_sort", k, v)
    n = k.n
    if n <= 1:
        return
    count, places, scatter, scatter_values = _kernels(k.dtype)
    nb = min(_MAX_BLOCKS, -(-n // _BLOCK))
    bs = -(-n // nb)
    h = ti.ndarray(ti.i32, nb * RADIX)

    def work(a: Array1D):
        """Two buffers to sort between: an ndarray is its own first one; a field is copied into one."""
        first = a.obj if a.kind == "ndarray" else a.scratch(n)
        if a.kind == "field":
            copy(a.obj, a.offset, first, 0, n, "field", "ndarray")
        return [first, a.scratch(n)]

    kb = work(k)
    vb = work(v) if v is not None else None
    cur = 0
    for shift in range(0, _KEY_TYPES[k.dtype], 8):
        count(kb[cur], n, nb, bs, shift, h)
        if places(h, n, nb):
            continue  # every key has this digit: the order stays
        if vb is None:
            scatter(kb[cur], kb[1 - cur], n, nb, bs, shift, h)
        else:
            scatter_values(kb[cur], kb[1 - cur], vb[cur], vb[1 - cur], n, nb, bs, shift, h)
        cur = 1 - cur
    for a, bufs in ((k, kb), (v, vb)):
        if a is None or bufs is None:
            continue
        if a.kind == "field":
            copy(bufs[cur], 0, a.obj, a.offset, n, "ndarray", "field")
        elif cur == 1:
            copy(bufs[1], 0, a.obj, 0, n, "ndarray", "ndarray")
