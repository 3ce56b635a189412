# mypy: disable-error-code="valid-type, index"
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
from simgrad.algorithms._containers import Array1D, annotation, copy, not_on_a_tape, python_scope
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


@ti.kernel
def places(h: ti.types.ndarray(), n: ti.i32, nb: ti.i32) -> ti.i32:
    """Block counts -> each (block, digit)'s first output place, digit-major (digit d's keys block by block,
    then digit d + 1's: that order is what makes the sort stable); 1 when one digit holds all n keys."""
    trivial = 0
    run = 0
    ti.loop_config(serialize=True)
    for d in range(RADIX):
        start = run
        for b in range(nb):
            c = h[b * RADIX + d]
            h[b * RADIX + d] = run
            run += c
        if run - start == n:
            trivial = 1
    return trivial


_KERNELS: dict = {}


def _kernels(kdt, kinds: tuple):
    """The count and scatter kernels for keys of one dtype and the containers' kinds: (keys from, keys to)
    or (keys from, keys to, values from, values to), each "field" or "ndarray". Made once per such key."""
    if (kdt, kinds) in _KERNELS:
        return _KERNELS[kdt, kinds]
    bits = order_bits(kdt)
    wide = ti.u64 if _KEY_TYPES[kdt] == 64 else ti.u32
    src_ann, dst_ann = annotation(kinds[0]), annotation(kinds[1])

    @ti.func
    def digit(x, shift):
        return ti.cast((bits(x) >> ti.cast(shift, wide)) & wide(RADIX - 1), ti.i32)

    @ti.kernel
    def count(keys: src_ann, off: ti.i32, n: ti.i32, nb: ti.i32, bs: ti.i32, shift: ti.i32,
              h: ti.types.ndarray()):
        ti.loop_config(block_dim=1)
        for b in range(nb):  # h[b * RADIX + d]: block b's keys with digit d (a block's counts are its own)
            for d in range(RADIX):
                h[b * RADIX + d] = 0
            for i in range(b * bs, ti.min(b * bs + bs, n)):
                k = b * RADIX + digit(keys[i + off], shift)
                h[k] = h[k] + 1

    if len(kinds) == 2:
        @ti.kernel
        def scatter(src: src_ann, soff: ti.i32, dst: dst_ann, doff: ti.i32, n: ti.i32, nb: ti.i32, bs: ti.i32,
                    shift: ti.i32, h: ti.types.ndarray()):
            ti.loop_config(block_dim=1)
            for b in range(nb):  # in order within a block, from the block's places for each digit
                for i in range(b * bs, ti.min(b * bs + bs, n)):
                    x = src[i + soff]
                    k = b * RADIX + digit(x, shift)
                    p = h[k]
                    h[k] = p + 1
                    dst[p + doff] = x

        _KERNELS[kdt, kinds] = count, scatter
        return count, scatter
    vsrc_ann, vdst_ann = annotation(kinds[2]), annotation(kinds[3])

    @ti.kernel
    def scatter_values(src: src_ann, soff: ti.i32, dst: dst_ann, doff: ti.i32, vsrc: vsrc_ann, vsoff: ti.i32,
                       vdst: vdst_ann, vdoff: ti.i32, n: ti.i32, nb: ti.i32, bs: ti.i32, shift: ti.i32,
                       h: ti.types.ndarray()):
        ti.loop_config(block_dim=1)
        for b in range(nb):
            for i in range(b * bs, ti.min(b * bs + bs, n)):
                x = src[i + soff]
                k = b * RADIX + digit(x, shift)
                p = h[k]
                h[k] = p + 1
                dst[p + doff] = x
                vdst[p + vdoff] = vsrc[i + vsoff]

    _KERNELS[kdt, kinds] = count, scatter_values
    return count, scatter_values


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
    nb = min(_MAX_BLOCKS, -(-n // _BLOCK))
    bs = -(-n // nb)
    h = ti.ndarray(ti.i32, nb * RADIX)
    # the two buffers each pass goes between: the user's container (its offset) and a scratch ndarray
    kb = [(keys, k.kind, k.offset), (k.scratch(n), "ndarray", 0)]
    vb = [(values, v.kind, v.offset), (v.scratch(n), "ndarray", 0)] if v is not None else None
    cur = 0
    for shift in range(0, _KEY_TYPES[k.dtype], 8):
        (ks, kks, kso), (kd, kkd, kdo) = kb[cur], kb[1 - cur]
        if vb is None:
            count, scatter = _kernels(k.dtype, (kks, kkd))
            args: tuple = (ks, kso, kd, kdo)
        else:
            (vs, vks, vso), (vd, vkd, vdo) = vb[cur], vb[1 - cur]
            count, scatter = _kernels(k.dtype, (kks, kkd, vks, vkd))
            args = (ks, kso, kd, kdo, vs, vso, vd, vdo)
        count(ks, kso, n, nb, bs, shift, h)
        if places(h, n, nb):
            continue  # every key has this digit: the order stays
        scatter(*args, n, nb, bs, shift, h)
        cur = 1 - cur
    if cur == 1:  # an odd number of passes moved the elements: they are in the scratch buffers
        for bufs in (kb, vb):
            if bufs is not None:
                (src, _, _), (dst, kind, off) = bufs[1], bufs[0]
                copy(src, 0, dst, off, n, "ndarray", kind)
