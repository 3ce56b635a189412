"""Quant fields become integer IR on their physical cells, before the parallel analyses and codegen (so every
target gets them): the one place that knows how Taichi 1.7.4 codes quantized values (QuanTaichi).

A GLOBAL_PTR into a quant field (FieldRef.quant, ir/fieldref.py QuantSlot) is pointed at the field's cell (a
FieldRef of the physical unsigned type, same layout), and each access through it is expanded:
- a load: load the cell; shift the value's bits to the top and back (arithmetic for signed: sign
  extension), then as the kind says: an int converts to its compute type, fixed point is
  `float(digits) * scale`, a float rebuilds f32 bits from digits and exponent (a shared exponent
  renormalises the digits with a count of leading zeros);
- a store: the value coded into bits (fixed: `(int)(v / scale +- 0.5)`; float: rounded to nearest, the
  exponent re-biased and flushed to zero below range), merged into the cell by a compare-and-swap loop
  (ATOMIC kind "cas") that replaces only the value's bits, so stores of neighbouring values in parallel
  loops never lose each other; a value that fills the whole cell is a plain store;
- an atomic: the same loop, the new bits computed from the old value inside it (int, fixed: integer
  arithmetic on the digits, fixed adds the coded operand as Taichi does); on a quant float, as Taichi, a
  load, the operation and a store (not atomic);
- with a shared exponent, a store recodes every float sharing it against the largest exponent.
Overflows wrap as Taichi's do (no clamping): an int keeps its low bits, a float's exponent spills."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import FieldRef, QuantSlot
from simgrad.ir.nodes import Block, Kernel, Stmt
from simgrad.ir.ops import Op

_SIGNED = {dt.u8: dt.i8, dt.u16: dt.i16, dt.u32: dt.i32, dt.u64: dt.i64}
_UNSIGNED = {dt.i8: dt.u8, dt.i16: dt.u16, dt.i32: dt.u32, dt.i64: dt.u64}
_ACCESS = (Op.GLOBAL_LOAD, Op.GLOBAL_STORE, Op.ATOMIC)


def expand_quant(kernel: Kernel) -> bool:
    state = _State()
    _block(kernel.body, state)
    return state.changed


class _State:
    def __init__(self) -> None:
        self.cells: dict[tuple, FieldRef] = {}  # one record per physical cell layout
        self.slots: dict[int, QuantSlot] = {}  # id(GLOBAL_PTR) -> the quant slot it pointed into
        self.repl: dict[int, Stmt] = {}  # id(replaced load/atomic) -> its value
        self.changed = False

    def cell(self, f: FieldRef, slot: QuantSlot) -> FieldRef:
        if f.quant is None:  # already the cell's record
            return f
        key = (f.layout, f.offset, f.levels, f.value_offset, slot.physical)
        ref = self.cells.get(key)
        if ref is None:
            ref = FieldRef(f"{f.name}.bits", slot.physical, f.layout, f.offset, owner=f.owner, levels=f.levels,
                           value_offset=f.value_offset)
            self.cells[key] = ref
        return ref

    def quant_of(self, ptr: Stmt) -> QuantSlot | None:
        """The quant slot a pointer points into (before or after slot_of retargeted it), else None."""
        if ptr.op is not Op.GLOBAL_PTR:
            return None
        slot = self.slots.get(id(ptr))
        target = ptr.attrs["target"]
        return slot if slot is not None else target.quant if isinstance(target, FieldRef) else None

    def slot_of(self, ptr: Stmt) -> QuantSlot | None:
        if ptr.op is not Op.GLOBAL_PTR:
            return None
        slot = self.slots.get(id(ptr))
        if slot is not None:
            return slot
        target = ptr.attrs["target"]
        if not isinstance(target, FieldRef) or target.quant is None:
            return None
        slot = target.quant
        ptr.attrs["target"] = self.cell(target, slot)  # every user of the pointer is expanded below
        ptr.type = slot.physical
        self.slots[id(ptr)] = slot
        return slot


def _block(block: Block, state: _State) -> None:
    fused, dropped = _fusions(block, state)
    out: list[Stmt] = []
    for s in block.stmts:
        if state.repl:
            s.operands = tuple(state.repl.get(id(o), o) for o in s.operands)
        if id(s) in dropped:  # stored by the fused store of its group, further down
            continue
        slot = state.slot_of(s.operands[0]) if s.op in _ACCESS and s.operands else None
        if slot is None:
            for blk in s.blocks:
                _block(blk, state)
            out.append(s)
            continue
        scratch = Block(block.parent)
        b = Builder(scratch)
        b.loc = s.loc
        q = _Quant(b, slot, s.operands[0])
        if s.op is Op.GLOBAL_LOAD:
            state.repl[id(s)] = q.load()
        elif s.op is Op.GLOBAL_STORE:
            members = fused.get(id(s), [(slot, s.operands[1])])
            q.store([(m, state.repl.get(id(v), v)) for m, v in members])
        else:
            state.repl[id(s)] = q.atomic(s.attrs["kind"], s.operands[1])
        for x in scratch.stmts:
            x.block = block
        out += scratch.stmts
        state.changed = True
    block.stmts = out


def _fusions(block: Block, state: _State) -> tuple[dict, set]:
    """Taichi's store fusion (optimize_bit_struct_stores.cpp): stores to members of one BitpackedFields cell in
    a run of a block with no control statement between become one store at the last of them, so a shared
    exponent is chosen once for all the new values (stored one by one, each would recode the others' already
    rounded digits). A load or atomic of the cell's field between two stores ends the run (Taichi: a load).
    Returns ({id(last store): [(slot, value), ...]}, ids of the stores it replaces)."""
    fused: dict[int, list] = {}
    dropped: set[int] = set()
    runs: dict[tuple, list[Stmt]] = {}

    def flush(key=None):
        for k in [key] if key is not None else list(runs):
            stores = runs.pop(k, [])
            if len(stores) > 1:
                fused[id(stores[-1])] = [(state.quant_of(x.operands[0]), x.operands[1]) for x in stores]
                dropped.update(id(x) for x in stores[:-1])

    for s in block.stmts:
        if s.blocks:
            flush()
            continue
        if s.op not in _ACCESS or not s.operands:
            continue
        slot = state.quant_of(s.operands[0])
        if slot is None or slot.array:
            continue
        cell = state.cell(s.operands[0].attrs["target"], slot)
        if s.op is Op.GLOBAL_STORE:
            index = tuple(("c", o.attrs["value"]) if o.op is Op.CONST else id(o) for o in s.operands[0].operands)
            runs.setdefault((id(cell), index), []).append(s)
        else:  # a read of the cell (at any index: it may alias) ends its runs
            for k in [k for k in runs if k[0] == id(cell)]:
                flush(k)
    flush()
    return fused, dropped


class _Quant:
    """The expansion of the accesses through one pointer `ptr` to a cell holding `slot`'s value."""

    def __init__(self, b: Builder, slot: QuantSlot, ptr: Stmt):
        self.b, self.q, self.ptr = b, slot, ptr
        assert slot.compute is not None
        self.compute: dt.DataType = slot.compute
        self.P = slot.physical
        self.W = slot.physical.bits
        self.off = self._offset(ptr)

    # -- bits -------------------------------------------------------------------------------------------
    def _offset(self, ptr: Stmt) -> Stmt | int:
        """The value's first bit: a constant in a bit_struct, `element number * bits` in a quant_array."""
        q, b = self.q, self.b
        if not q.array:
            return q.offset
        number: Stmt | None = None
        for position, modulus, weight in q.array:
            d = b.cast(ptr.operands[position], self.P)
            d = b.raw_mod(d, modulus)
            term = b.mul(d, weight) if weight != 1 else d
            number = term if number is None else b.add(number, term)
        assert number is not None
        return b.mul(number, q.bits) if q.bits != 1 else number

    def _shifted(self, v: Stmt, off: Stmt | int) -> Stmt:
        """v << off (v of the physical type)."""
        if isinstance(off, int):
            return self.b.shl(v, off) if off else v
        return self.b.shl(v, off)

    def mask(self, bits: int, off: Stmt | int) -> Stmt:
        m = (1 << bits) - 1
        if isinstance(off, int):
            return self.b.const(m << off, self.P)
        return self.b.shl(self.b.const(m, self.P), off)

    def extract(self, cell: Stmt, off: Stmt | int, bits: int, signed: bool) -> Stmt:
        """The `bits` bits at `off`: shifted up to the top, then down (sign-extending when signed). The result
        is of the physical type, or of its signed counterpart when signed."""
        b, W = self.b, self.W
        left = W - off - bits if isinstance(off, int) else b.sub(b.const(W - bits, self.P), off)
        top = self._shifted(cell, left) if not isinstance(left, int) or left else cell
        if signed:
            return b.shr(b.cast(top, _SIGNED[self.P]), W - bits) if W != bits else b.cast(top, _SIGNED[self.P])
        return b.shr(top, W - bits) if W != bits else top

    def to_cell(self, v: Stmt) -> Stmt:
        """An integer value as the physical type, zero-extended (Taichi's IntCast(v, physical, false))."""
        t = v.vtype
        if t.is_signed:
            v = self.b.cast(v, _UNSIGNED[t])
        return self.b.cast(v, self.P)

    def placed(self, v: Stmt, bits: int, off: Stmt | int) -> tuple[Stmt, Stmt]:
        """(bits of integer v placed at off, their mask)."""
        return self._shifted(self.to_cell(v), off), self.mask(bits, off)

    def merge(self, old: Stmt, val: Stmt, mask: Stmt) -> Stmt:
        b = self.b
        return b.bit_or(b.bit_and(old, b.bit_not(mask)), b.bit_and(val, mask))

    def cas(self, update) -> Stmt:
        """Replace the cell by update(old) atomically: a compare-and-swap loop. Returns the old cell."""
        b, P = self.b, self.P
        var = b.emit(Op.ALLOCA, P)
        b.emit(Op.LOCAL_STORE, None, (var, b.emit(Op.GLOBAL_LOAD, P, (self.ptr,))))
        loop = b.emit(Op.WHILE, None, (), nblocks=1)
        with b.inside(loop.blocks[0]):
            old = b.emit(Op.LOCAL_LOAD, P, (var,))
            got = b.emit(Op.ATOMIC, P, (self.ptr, old, update(old)), {"kind": "cas"})
            done = b.emit(Op.IF, None, (b.eq(got, old),), nblocks=2)
            with b.inside(done.blocks[0]):
                b.emit(Op.BREAK, None)
            with b.inside(done.blocks[1]):
                b.emit(Op.LOCAL_STORE, None, (var, got))
        return b.emit(Op.LOCAL_LOAD, P, (var,))

    # -- values ---------------------------------------------------------------------------------------
    def decode(self, cell: Stmt, q: QuantSlot | None = None) -> Stmt:
        q = q or self.q
        b = self.b
        off = self.off if q is self.q else q.offset
        if q.kind == "float":
            return self._float_decode(cell, q, off, q.bits, q.signed)
        raw = self.extract(cell, off, q.bits, q.signed)
        compute = q.compute or self.compute
        if q.kind == "int":
            return b.cast(raw, compute)
        digits = b.cast(raw, dt.i32 if q.signed else dt.u32)
        return b.mul(b.cast(digits, compute), b.const(q.scale, compute))

    def encode(self, v: Stmt, q: QuantSlot) -> Stmt:
        """An int's or fixed value's digits (an integer of the compute or digits type)."""
        b = self.b
        if q.kind == "int":
            return v
        t = v.vtype
        scaled = b.mul(v, b.const(1.0 / q.scale, t))
        ut = dt.u32 if t.bits == 32 else dt.u64
        sign = b.bit_and(b.emit(Op.BITCAST, ut, (scaled,)), b.const(1 << (t.bits - 1), ut))
        half = b.emit(Op.BITCAST, t, (b.bit_or(sign, b.emit(Op.BITCAST, ut, (b.const(0.5, t),))),))
        return b.cast(b.add(scaled, half), dt.i32 if q.signed else dt.u32)  # rounds half away from zero

    def load(self) -> Stmt:
        return self.decode(self.b.emit(Op.GLOBAL_LOAD, self.P, (self.ptr,)))

    def store(self, members: list) -> None:
        """Store [(slot, value)] into this cell at once (one member, or a fused group of a BitpackedFields):
        a shared exponent is recoded for all its users, from the new values and the others' current ones."""
        given = {m.offset: (m, v) for m, v in members}  # a member stored twice keeps its last value
        groups = {m.exp_offset: m for m, _v in given.values() if m.kind == "float" and m.shared}
        plain = [(m, v) for m, v in given.values() if not (m.kind == "float" and m.shared)]
        reads_old = any(o not in given for g in groups.values() for o, _bits, _sg in g.shared)
        covered = 0
        for m, _v in plain:
            covered |= ((1 << m.bits) - 1) << m.offset if not m.array else 0
            covered |= ((1 << m.exp_bits) - 1) << m.exp_offset if m.kind == "float" else 0
        for g in groups.values():
            covered |= ((1 << g.exp_bits) - 1) << g.exp_offset
            for o, bits, _sg in g.shared:
                covered |= ((1 << bits) - 1) << o
        digits = [(m, self.encode(v, m)) if m.kind != "float" else (m, v) for m, v in plain]

        def update(old: Stmt | None) -> tuple[Stmt, Stmt]:
            parts = []
            for m, v in digits:
                if m.kind == "float":  # its exponent is not masked: an overflow spills, as in Taichi
                    parts.append(self._float_bits(v, m))
                    continue
                x, y = self.placed(v, m.bits, self.off if m is self.q else m.offset)
                parts.append((self.b.bit_and(x, y), y))  # the value's own bits only (a plain store ORs them)
            for g in groups.values():
                values = {o: given[o][1] for o, _bits, _sg in g.shared if o in given}
                parts.append(self._shared_bits(old, g, values))
            val, mask = parts[0]
            for x, y in parts[1:]:
                val, mask = self.b.bit_or(val, x), self.b.bit_or(mask, y)
            return val, mask

        # every member's bits new (Taichi's atomic demotion of a store of all members): a plain store
        if not reads_old and covered == (1 << (self.q.used or self.W)) - 1:
            self.b.emit(Op.GLOBAL_STORE, None, (self.ptr, update(None)[0]))
        else:
            self.cas(lambda old: self.merge(old, *update(old)))

    def atomic(self, kind: str, v: Stmt) -> Stmt:
        q, b = self.q, self.b
        if q.kind == "float":  # Taichi demotes these to a read-modify-write (not atomic)
            old = self.load()
            self.store([(q, _combine(b, kind, old, v))])
            return old
        if q.kind == "fixed" and kind == "add":  # Taichi adds the coded operand to the digits
            dv = self.encode(v, q)

            def added(old: Stmt) -> Stmt:
                d = b.cast(self.extract(old, self.off, q.bits, q.signed), dv.vtype)
                return self.merge(old, *self.placed(b.add(d, dv), q.bits, self.off))
            return self.decode(self.cas(added))

        def update(old: Stmt) -> Stmt:
            new = _combine(b, kind, self.decode(old), v)
            return self.merge(old, *self.placed(self.encode(new, q), q.bits, self.off))
        return self.decode(self.cas(update))

    # -- quant floats (f32 compute; Taichi's codegen_llvm_quant.cpp arithmetic) -------------------------
    def _conv(self, exp: Stmt, q: QuantSlot) -> Stmt:
        """The exponent bias difference, 0 for a zero exponent when the exponent is narrower than f32's."""
        b = self.b
        conv = 127 - (1 << (q.exp_bits - 1)) + 1
        if q.exp_bits >= 8:
            return b.const(conv, dt.i32)
        return b.select(b.ne(exp, b.const(0, dt.i32)), b.const(conv, dt.i32), b.const(0, dt.i32))

    def _float_decode(self, cell: Stmt, q: QuantSlot, off: int | Stmt, bits: int, signed: bool) -> Stmt:
        """The f32 value of the digits at `off` (`bits` wide) with q's exponent."""
        b = self.b
        u = dt.u32
        d = bits - (1 if signed else 0)
        given = b.cast(self.extract(cell, off, bits, signed), dt.i32)
        raw = b.bit_and(b.cast(given, u), (1 << bits) - 1)
        exp = b.cast(self.extract(cell, q.exp_offset, q.exp_bits, False), dt.i32)
        conv = self._conv(exp, q)
        sign: Stmt | None = None
        if q.shared:
            digits = raw
            if signed:
                sign = b.bit_and(digits, 1 << d)
                digits = b.shl(b.bit_xor(digits, sign), 1)
                sign = b.shl(sign, 31 - d)
            extra = b.sub(b.const(31 - d, dt.i32), _clz32(b, digits))
            conv = b.add(conv, extra)
            if not signed:
                conv = b.add(conv, 1)
            digits = b.shl(digits, b.cast(b.sub(b.const(23 - d, dt.i32), extra), u))
        else:
            digits = b.shl(raw, 23 - d)
        f = b.bit_or(b.shl(b.cast(b.add(exp, conv), u), 23), b.bit_and(digits, (1 << 23) - 1))
        if q.shared:
            zero = b.bit_or(b.eq(exp, b.const(0, dt.i32)), b.eq(given, b.const(0, dt.i32)))
            f = b.select(zero, b.const(0, u), f)
        if signed:
            f = b.bit_or(f, sign if sign is not None else b.shl(b.bit_and(digits, 1 << 23), 8))
        return b.emit(Op.BITCAST, dt.f32, (f,))

    def _float_bits(self, v: Stmt, q: QuantSlot) -> tuple[Stmt, Stmt]:
        """A float with its own exponent: (digit and exponent bits, their mask), rounded to nearest."""
        b = self.b
        u = dt.u32
        d = q.bits - (1 if q.signed else 0)
        fb = b.emit(Op.BITCAST, u, (v,))
        if d < 23:
            fb = b.add(fb, 1 << (22 - d))  # a carry out of the digits increments the exponent, as wanted
        exp = b.bit_and(b.shr(fb, 23), 255)
        digits = b.bit_and(b.shr(fb, 23 - d), (1 << d) - 1)
        if q.signed:
            digits = b.bit_or(digits, b.shr(b.bit_and(fb, 1 << 31), 31 - d))
        e = b.cast(exp, dt.i32)
        e = b.max(b.sub(e, self._conv(e, q)), 0)
        digits = b.select(b.ne(e, b.const(0, dt.i32)), digits, b.const(0, u))  # flush to zero
        ev, em = self.placed(e, q.exp_bits, q.exp_offset)
        dv, dm = self.placed(digits, q.bits, q.offset)
        return b.bit_or(ev, dv), b.bit_or(em, dm)

    def _shared_bits(self, old: Stmt | None, q: QuantSlot, values: dict) -> tuple[Stmt, Stmt]:
        """Every float sharing q's exponent recoded against the largest exponent: the values in `values`
        (by digit offset) and the others' current ones (from `old`). Returns (bits, mask)."""
        b = self.b
        u = dt.u32
        floats = []
        for o, bits, sg in q.shared:
            if o in values:
                floats.append(values[o])
            else:
                assert old is not None
                floats.append(self._float_decode(old, q, o, bits, sg))
        fbits = [b.emit(Op.BITCAST, u, (x,)) for x in floats]
        exps = [b.bit_and(b.shr(x, 23), 255) for x in fbits]
        top = exps[0]
        for e in exps[1:]:
            top = b.max(top, e)
        stored = b.max(b.sub(b.cast(top, dt.i32), self._conv(b.cast(top, dt.i32), q)), 0)
        val, mask = self.placed(stored, q.exp_bits, q.exp_offset)
        for (o, bits, sg), x, e in zip(q.shared, fbits, exps):
            d = bits - (1 if sg else 0)
            implicit = b.shl(b.cast(b.ne(e, b.const(0, u)), u), 23)
            digits = b.bit_or(b.bit_or(b.bit_and(x, (1 << 23) - 1), 1 << 23), implicit)
            digits = b.shr(digits, b.min(b.sub(top, e), 31))
            rs = 24 - d
            digits = b.min(b.add(digits, 1 << (rs - 1)), (1 << 24) - 1)  # round to nearest, no overflow
            digits = b.shr(digits, rs)
            if sg:
                digits = b.bit_or(digits, b.shr(b.bit_and(x, 1 << 31), 31 - d))
            dv, dm = self.placed(digits, bits, o)
            val, mask = b.bit_or(val, dv), b.bit_or(mask, dm)
        return val, mask


def _clz32(b: Builder, x: Stmt) -> Stmt:
    """Leading zeros of a u32 (32 for 0), as an i32: from the exponent of its exact f64 value."""
    bits = b.emit(Op.BITCAST, dt.u64, (b.cast(x, dt.f64),))
    e = b.sub(b.cast(b.shr(bits, 52), dt.i32), 1023)
    return b.select(b.eq(x, b.const(0, dt.u32)), b.const(32, dt.i32), b.sub(b.const(31, dt.i32), e))


def _combine(b: Builder, kind: str, old: Stmt, v: Stmt) -> Stmt:
    if kind == "xchg":
        return v
    op = {"add": Op.ADD, "mul": Op.MUL, "min": Op.MIN, "max": Op.MAX, "and": Op.BIT_AND, "or": Op.BIT_OR,
          "xor": Op.BIT_XOR}[kind]
    return b.binary(op, old, v)
