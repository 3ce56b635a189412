"""LLVM IR for sparse SNodes: looking a cell up (SPARSE_CELL), acting on one (SPARSE_ACTION), and the two
helpers every kernel module that activates or frees gets: `@sg_sparse_alloc` (a block for a slot, under the
pool's spin lock) and `@sg_sparse_free` (zero a block and put it on the pool's free list). The pool table
and what its words mean are runtime/sparse.py's; passes/lower_access.py decides which level is looked up
how (read: an inactive cell is the zero block, write: activate it)."""

from __future__ import annotations

from simgrad.codegen.access import pointer_and_offsets
from simgrad.runtime import abi, ll
from simgrad.runtime import sparse as rt

_HELPERS = {batched: ll.load("sparse_alloc", CTX_SPARSE=abi.CTX_SPARSE, BATCH=rt.BATCH,
                              BATCHED="true" if batched else "false",
                              **{k: getattr(rt, k) for k in ll.parameters("sparse_alloc") if k.startswith("POOL_")})
            for batched in (True, False)}


def _helpers(g) -> None:
    g.module.declare("declare void @llvm.memset.p0.i64(ptr, i8, i64, i1)")
    helpers = _HELPERS[g.batched_alloc]
    if helpers not in g.module.functions:
        g.module.functions.append(helpers)


def _pool_word(f, pool: int, word: int) -> str:
    """A word of a pool's table entry, loaded where it is used (the table moves only between launches)."""
    tp, table, p, v = f.tmp("spt"), f.tmp("sptab"), f.tmp("spw"), f.tmp("spv")
    f.emit(f"{tp} = getelementptr i64, ptr %ctx, i64 {abi.CTX_SPARSE}")
    f.emit(f"{table} = load ptr, ptr {tp}, !invariant.load !0")
    f.emit(f"{p} = getelementptr i64, ptr {table}, i64 {pool * rt.POOL_WORDS + word}")
    f.emit(f"{v} = load ptr, ptr {p}, !invariant.load !0")
    return v


def lower_tree_root(g, f, s) -> None:
    r = f.tmp("rootaddr")
    f.emit(f"{r} = ptrtoint ptr {f.root(s.attrs['tree'])} to i64")
    f.names[s] = r
    f.addr_base[s] = (f.root(s.attrs["tree"]), ())


def _as_ptr(f, v: str) -> str:
    p = f.tmp("cp")
    f.emit(f"{p} = inttoptr i64 {v} to ptr")
    return p


def _as_int(f, p: str) -> str:
    r = f.tmp("ci")
    f.emit(f"{r} = ptrtoint ptr {p} to i64")
    return r


def _branch(f, cond: str, then_emit, else_emit=None) -> None:
    """if cond (i1) { then_emit() } else { else_emit() }; both emit straight-line code."""
    t, e, d = f.label("sthen"), f.label("selse"), f.label("sdone")
    f.emit(f"br i1 {cond}, label %{t}, label %{e}")
    f.start_block(t)
    then_emit()
    f.emit(f"br label %{d}")
    f.start_block(e)
    if else_emit is not None:
        else_emit()
    f.emit(f"br label %{d}")
    f.start_block(d)


def _slot_block(g, f, s, slot: str, level, mode: str) -> str:
    """The block a slot points to (pointer cell, dynamic list); when it is null, the zero block (read) or
    a new block (write)."""
    cur = f.tmp("blk")
    f.emit(f"{cur} = load atomic ptr, ptr {slot} monotonic, align 8")
    null = f.tmp("isnull")
    f.emit(f"{null} = icmp eq ptr {cur}, null")
    if mode == "write":
        _helpers(g)
        code = g.error_code("sparse_pool", s.loc, level.kind)
        t, d, pre = f.label("act"), f.label("actdone"), f.label("actpre")
        f.emit(f"br label %{pre}")
        f.start_block(pre)
        f.emit(f"br i1 {null}, label %{t}, label %{d}, !prof !1")
        f.start_block(t)
        new = f.tmp("newblk")
        f.emit(f"{new} = call ptr @sg_sparse_alloc(ptr %ctx, i64 {level.pool}, ptr {slot}, i64 {code}, "
               f"i32 {f.tid})")
        f.emit(f"br label %{d}")
        f.start_block(d)
        r = f.tmp("blkr")
        f.emit(f"{r} = phi ptr [{cur}, %{pre}], [{new}, %{t}]")
        g.need_branch_weights()
        return r
    zero = _pool_word(f, level.pool, rt.POOL_ZERO)
    r = f.tmp("blkr")
    f.emit(f"{r} = select i1 {null}, ptr {zero}, ptr {cur}")
    return r


def _mask_word(f, container: str, cell: str, level) -> tuple[str, str]:
    """(pointer to the u32 activity word of a bitmasked cell, its bit)."""
    w, wb, p, b, b32, bit = (f.tmp("mw") for _ in range(6))
    f.emit(f"{w} = lshr i64 {cell}, 5")
    f.emit(f"{wb} = mul i64 {w}, 4")
    f.emit(f"{p} = add i64 {container}, {level.mask_offset}")
    addr = f.tmp("mwa")
    f.emit(f"{addr} = add i64 {p}, {wb}")
    f.emit(f"{b} = and i64 {cell}, 31")
    f.emit(f"{b32} = trunc i64 {b} to i32")
    f.emit(f"{bit} = shl i32 1, {b32}")
    return _as_ptr(f, addr), bit


def _bit_set(f, word_ptr: str, bit: str) -> str:
    v, a, r = f.tmp("mv"), f.tmp("ma"), f.tmp("mset")
    f.emit(f"{v} = load atomic i32, ptr {word_ptr} monotonic, align 4")
    f.emit(f"{a} = and i32 {v}, {bit}")
    f.emit(f"{r} = icmp ne i32 {a}, 0")
    return r


def _slot(f, container: str, cell: str) -> str:
    """Pointer to the block slot of a pointer node's cell."""
    sa, so = f.tmp("sa"), f.tmp("so")
    f.emit(f"{so} = mul i64 {cell}, 8")
    f.emit(f"{sa} = add i64 {container}, {so}")
    return _as_ptr(f, sa)


def _cursor(f, pool: int) -> str:
    """This function's cursor over the lists of a dynamic node (runtime/ll/sparse_alloc.ll @sg_dyn_chunk):
    {header, first chunk, chunk number, chunk}, starting at no list (every word set: the walk reads them all)."""
    cur = f.cursors.get(pool)
    if cur is None:
        cur = f.cursors[pool] = f.tmp("dcur")
        f.prologue += [f"  {cur} = alloca [4 x i64], align 8", f"  store [4 x i64] zeroinitializer, ptr {cur}"]
    return cur


def _dyn_element(g, f, s, container: str, cell: str, level, mode: str) -> str:
    """The address of element `cell` of the dynamic list whose header is at `container`: cell // chunk links
    down its chain of chunks (from the function's cursor), then cell % chunk cells into that chunk (after its
    8-byte link). A write allocates the chunks it reaches; an index past the node's size reads the zero block
    and writes the discard block, rather than walking (and allocating) past the list's last chunk."""
    _helpers(g)
    hdr = _as_ptr(f, container)
    write = "true" if mode == "write" else "false"
    code = g.error_code("sparse_pool", s.loc, "dynamic") if mode == "write" else 0
    chunk = level.chunk
    k, r = "0", cell
    if chunk < level.ncells:
        inside, kk, kc, rr = f.tmp("din"), f.tmp("dk"), f.tmp("dkc"), f.tmp("dr")
        f.emit(f"{inside} = icmp ult i64 {cell}, {level.ncells}")
        f.emit(f"{kk} = udiv i64 {cell}, {chunk}")
        f.emit(f"{kc} = mul i64 {kk}, {chunk}")
        f.emit(f"{rr} = sub i64 {cell}, {kc}")
        k, r = f.tmp("dkk"), rr
        f.emit(f"{k} = select i1 {inside}, i64 {kk}, i64 0")
    firstp, f0, blk = f.tmp("dfp"), f.tmp("df0"), f.tmp("dch")
    f.emit(f"{firstp} = getelementptr i8, ptr {hdr}, i64 8")
    if mode == "write":  # the chunk's cells as the thread that linked it left them
        f.emit(f"{f0} = load atomic ptr, ptr {firstp} acquire, align 8")
    else:  # a plain load: a loop reading the list gets its first chunk hoisted (and may vectorise)
        f.emit(f"{f0} = load ptr, ptr {firstp}, align 8")
    if chunk >= level.ncells and mode != "write":  # one chunk: it, or the zero block while the list has none
        null = f.tmp("dnull")
        f.emit(f"{null} = icmp eq ptr {f0}, null")
        f.emit(f"{blk} = select i1 {null}, ptr {_pool_word(f, level.pool, rt.POOL_ZERO)}, ptr {f0}")
    else:
        f.emit(f"{blk} = call ptr @sg_dyn_chunk(ptr %ctx, i64 {level.pool}, ptr {hdr}, ptr {f0}, i64 {k}, "
               f"i1 {write}, i64 {code}, i32 {f.tid}, ptr {_cursor(f, level.pool)})")
    if chunk < level.ncells:  # past the node's size: the zero / discard block
        side = _pool_word(f, level.pool, rt.POOL_DISCARD if mode == "write" else rt.POOL_ZERO)
        sel = f.tmp("dsel")
        f.emit(f"{sel} = select i1 {inside}, ptr {blk}, ptr {side}")
        blk = sel
    off, off8, r_ = f.tmp("eo"), f.tmp("eo8"), f.tmp("ea")
    f.emit(f"{off} = mul i64 {r}, {level.cell_size}")
    f.emit(f"{off8} = add i64 {off}, 8")
    f.emit(f"{r_} = add i64 {_as_int(f, blk)}, {off8}")
    f.addr_base[s] = (blk, (off8,))  # the element's address: its chunk plus an offset (codegen/access.py)
    return r_


def lower_sparse_cell(g, f, s) -> None:
    container, cell = (f.v(o) for o in s.operands)
    level, mode = s.attrs["level"], s.attrs["mode"]
    kind = level.kind
    if kind == "pointer":
        blk = _slot_block(g, f, s, _slot(f, container, cell), level, mode)
        f.names[s] = _as_int(f, blk)
        f.addr_base[s] = (blk, ())
        return
    if kind == "dynamic":
        addr = _dyn_element(g, f, s, container, cell, level, mode)
        if mode == "write":  # the list now reaches at least this element
            n1, n32 = f.tmp("dn"), f.tmp("dn32")
            f.emit(f"{n1} = add i64 {cell}, 1")
            f.emit(f"{n32} = trunc i64 {n1} to i32")
            f.emit(f"atomicrmw max ptr {_as_ptr(f, container)}, i32 {n32} monotonic")
        f.names[s] = addr
        return
    # bitmasked: the cells are in the container (reads see what is stored, as in Taichi); a write sets the bit
    off, addr = f.tmp("bo"), f.tmp("ba")
    f.emit(f"{off} = mul i64 {cell}, {level.cell_size}")
    f.emit(f"{addr} = add i64 {container}, {off}")
    based = pointer_and_offsets(f, s.operands[0])
    if based is not None:
        f.addr_base[s] = (based[0], (*based[1], off))
    if mode == "write":
        word, bit = _mask_word(f, container, cell, level)
        is_set = _bit_set(f, word, bit)
        _branch(f, is_set, lambda: None, lambda: f.emit(f"atomicrmw or ptr {word}, i32 {bit} monotonic"))
    f.names[s] = addr


def _list_entry(f, s) -> str:
    """Pointer to entry operands[0] of the struct-for's list (runtime/sparse.py: MAX_LISTS per pool)."""
    level = s.attrs["level"]
    base = _pool_word(f, level.pool, rt.POOL_LISTS)
    k64, p = f.tmp("lk"), f.tmp("lp")
    f.emit(f"{k64} = sext i32 {f.v(s.operands[0])} to i64")
    f.emit(f"{p} = getelementptr i32, ptr {base}, i64 {s.attrs['list'] * level.total_cells}")
    e = f.tmp("le")
    f.emit(f"{e} = getelementptr i32, ptr {p}, i64 {k64}")
    return e


def lower_sparse_action(g, f, s) -> None:
    op = s.attrs["op"]
    if op == "list_get":
        r = f.tmp("lv")
        f.emit(f"{r} = load i32, ptr {_list_entry(f, s)}")
        f.names[s] = r
        return
    if op == "list_set":
        f.emit(f"store i32 {f.v(s.operands[1])}, ptr {_list_entry(f, s)}")
        f.names[s] = "0"
        return
    container, cell = (f.v(o) for o in s.operands)
    level = s.attrs["level"]
    kind = level.kind
    r = f.tmp("act")
    if kind == "dynamic" and op in ("activate", "deactivate"):
        if op == "activate":  # the chunks up to the cell's, the length unchanged
            _dyn_element(g, f, s, container, cell, level, "write")
        else:
            f.emit(f"call void @sg_dyn_clear(ptr %ctx, i64 {level.pool}, ptr {_as_ptr(f, container)})")
            f.emit(f"store i64 0, ptr {_cursor(f, level.pool)}")  # the cursor's chunks are free now
            _helpers(g)
        f.emit(f"{r} = add i32 0, 0")
        f.names[s] = r
        return
    if kind == "pointer":
        slot = _slot(f, container, cell)
        if op == "is_active":
            cur, c = f.tmp("cur"), f.tmp("c")
            f.emit(f"{cur} = load atomic ptr, ptr {slot} monotonic, align 8")
            f.emit(f"{c} = icmp ne ptr {cur}, null")
            f.emit(f"{r} = zext i1 {c} to i32")
        elif op == "activate":
            _slot_block(g, f, s, slot, level, "write")
            f.emit(f"{r} = add i32 0, 0")
        elif op == "deactivate":
            _helpers(g)
            old, c = f.tmp("old"), f.tmp("c")
            f.emit(f"{old} = atomicrmw xchg ptr {slot}, ptr null monotonic")
            f.emit(f"{c} = icmp ne ptr {old}, null")
            _branch(f, c, lambda: f.emit(f"call void @sg_sparse_free(ptr %ctx, i64 {level.pool}, ptr {old})"))
            f.emit(f"{r} = add i32 0, 0")
        else:
            raise AssertionError(f"internal: {op} on a {kind} node")
        f.names[s] = r
        return
    if kind == "dynamic":
        lp = _as_ptr(f, container)
        if op == "length":
            n = f.tmp("len")
            f.emit(f"{n} = load atomic i32, ptr {lp} monotonic, align 4")
            f.emit(f"{r} = call i32 @llvm.smin.i32(i32 {n}, i32 {level.ncells})")
            g.module.declare("declare i32 @llvm.smin.i32(i32, i32)")
        elif op == "append_slot":
            f.emit(f"{r} = atomicrmw add ptr {lp}, i32 1 monotonic")
        elif op == "is_active":
            n, c, c32 = f.tmp("len"), f.tmp("c"), f.tmp("c32")
            f.emit(f"{n} = load atomic i32, ptr {lp} monotonic, align 4")
            f.emit(f"{c32} = trunc i64 {cell} to i32")
            f.emit(f"{c} = icmp slt i32 {c32}, {n}")
            f.emit(f"{r} = zext i1 {c} to i32")
        else:
            raise AssertionError(f"internal: {op} on a dynamic node")
        f.names[s] = r
        return
    # bitmasked
    word, bit = _mask_word(f, container, cell, level)
    if op == "is_active":
        f.emit(f"{r} = zext i1 {_bit_set(f, word, bit)} to i32")
    elif op == "activate":
        f.emit(f"atomicrmw or ptr {word}, i32 {bit} monotonic")
        f.emit(f"{r} = add i32 0, 0")
    elif op == "deactivate":  # as Taichi: only the bit; the cell's data stays (a direct read still sees it)
        nb = f.tmp("nb")
        f.emit(f"{nb} = xor i32 {bit}, -1")
        f.emit(f"atomicrmw and ptr {word}, i32 {nb} monotonic")
        f.emit(f"{r} = add i32 0, 0")
    else:
        raise AssertionError(f"internal: {op} on a bitmasked node")
    f.names[s] = r
