"""Random tile loops for passes/lanes_memory.py's uniform counted loops: each program is a 2-D parallel loop (a
struct-for or an ndrange with offsets, rows of random length) whose iterations count to a tile's entry of a count
field, at a tile index drawn from forms the analysis must judge (`j // 8`, `(j + 8) // 8`, `j >> 3`, `j % 16 // 8`
are uniform in aligned groups; `(j + 1) // 8`, `j // 3`, `j // 2` are not), load a shared list and a table, and
store the iteration's own elements under a condition. Run with the rewrite off (simt_lanes=0), at the host's width
(-1) and at 8 lanes: every output agrees bit for bit, and the host's width takes a share of the programs."""

from __future__ import annotations

import importlib.util
import random

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.ops import Op

TILES = ["j // 8", "j // 4", "j // 16", "(j + 8) // 8", "(j + 1) // 8", "j >> 3", "(j - 4) // 4", "j % 16 // 8",
         "i", "i // 3", "j // 8 + i", "5", "j // 3", "j // 4 * 2 - i", "j // 2"]


def _program(seed: int) -> str:
    r = random.Random(seed)
    rows, cols = r.randint(2, 9), r.randint(3, 70)
    a0, b0 = r.choice([(0, 0), (0, 0), (r.randint(-3, 5), r.choice([0, 4, 8, -8, 3]))])
    loop = "for i, j in out_f" if (a0, b0) == (0, 0) else \
        f"for i, j in ti.ndrange(({a0}, {a0 + rows}), ({b0}, {b0 + cols}))"
    tile_u, tile_v = r.choice(TILES), r.choice(TILES)
    entry = r.choice(["lst[u, v, t]", f"lst[u, ti.min(ti.max({r.choice(TILES)}, 0), 15), t]"])
    extra = r.choice(["", "", " + tab[(e + j) % 32]"])  # an index of the lane's own: a gather
    return f'''import simgrad as ti

cnt = ti.field(ti.i32, shape=(16, 16))
lst = ti.field(ti.i32, shape=(16, 16, 8))
tab = ti.field(ti.f32, shape=32)
out_f = ti.field(ti.f32, shape=({rows}, {cols}))
out_i = ti.field(ti.i32, shape=({rows}, {cols}))
hits = ti.field(ti.i32, shape=({rows}, {cols}, 4))


@ti.kernel
def k():
    {loop}:
        u = ti.min(ti.max({tile_u}, 0), 15)
        v = ti.min(ti.max({tile_v}, 0), 15)
        acc = ti.cast(j, ti.f32) * 0.01
        m = 0
        for t in range(cnt[u, v]):
            e = {entry}
            acc = acc * {r.uniform(0.3, 0.9):.3f} + tab[e] * (j - t){extra}
            if acc > {r.uniform(-1, 1):.3f}:
                hits[i - ({a0}), j - ({b0}), t % 4] = t + 1
            m += 1
        out_f[i - ({a0}), j - ({b0})] = acc
        out_i[i - ({a0}), j - ({b0})] = m
'''


def _run(path, lanes: int):
    ti.init(arch=ti.cpu, simt_lanes=lanes, cpu_max_num_threads=1)
    spec = importlib.util.spec_from_file_location(f"uniform_fuzz_{lanes}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rng = np.random.default_rng(1)
    mod.cnt.from_numpy(rng.integers(0, 9, (16, 16)).astype(np.int32))
    mod.lst.from_numpy(rng.integers(0, 32, (16, 16, 8)).astype(np.int32))
    mod.tab.from_numpy(rng.uniform(-1, 1, 32).astype(np.float32))
    mod.k()
    rewritten = any(s.op is Op.RANGE_FOR and s.attrs.get("simt") for s in mod.k._instance_for((), "").ir.body.stmts)
    return [mod.out_f.to_numpy().view(np.uint32), mod.out_i.to_numpy(), mod.hits.to_numpy()], rewritten


@pytest.mark.parametrize("chunk", range(4))
def test_random_tile_loops_agree_bit_for_bit(tmp_path, chunk):
    taken = 0
    for seed in range(chunk * 12, chunk * 12 + 12):
        text = _program(seed)
        path = tmp_path / f"prog{seed}.py"
        path.write_text(text)
        off, was = _run(path, 0)
        assert not was
        for lanes in (-1, 8):
            on, was = _run(path, lanes)
            taken += was and lanes == -1
            for a, b in zip(off, on):
                np.testing.assert_array_equal(a, b, err_msg=f"simt_lanes={lanes}\n{text}")
    assert taken >= 2
