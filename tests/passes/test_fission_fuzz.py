"""Random scatter loops for passes/fission.py: each program is a particle loop computing random f32/f64 arithmetic
from the particle's data (nested if/else on it, stores to the particle's own elements, conditional ones too), then
updating random grid cells (indices from the particle's values) with random values, 2 to 5 cells of 1 to 3
components. Run unsplit and split (ti.init(fission_lanes=0 / 8), one thread, fast_math off), every output must
agree bit for bit; most programs must be split."""

from __future__ import annotations

import importlib.util
import random

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.ops import Op

N = 61  # particles: seven groups of 8 and a partial one
G = 12  # grid cells a side


class _Gen:
    def __init__(self, seed: int):
        self.r = random.Random(seed)

    def expr(self, depth=0) -> str:
        r = self.r
        leaves = ["u", "w", "q[p][0]", "q[p][1]", "h", f"{r.uniform(-2, 2):.3f}"]
        if depth > 2 or r.random() < 0.25:
            return r.choice(leaves)
        x, y = self.expr(depth + 1), self.expr(depth + 1)
        return r.choice([f"({x} + {y})", f"({x} - {y})", f"({x} * {y})", f"({x} / (ti.abs({y}) + 1.0))",
                         f"ti.sqrt(ti.abs({x}))", f"ti.exp(-ti.abs({x}))", f"ti.select({x} < {y}, {x}, {y})",
                         f"ti.max({x}, {y})"])

    def block(self, ind: str, depth: int) -> list[str]:
        r = self.r
        out = []
        for _ in range(r.randint(2, 5)):
            k = r.random()
            if k < 0.3:
                out.append(f"{ind}u = {self.expr()}")
            elif k < 0.5:
                out.append(f"{ind}w = {self.expr()}")
            elif k < 0.6:
                out.append(f"{ind}h += {self.expr(1)}")
            elif k < 0.75:
                out.append(f"{ind}q[p][{r.randint(0, 1)}] = {self.expr(1)}")  # the particle's own element
            elif depth < 2:
                out.append(f"{ind}if {self.expr(1)} {r.choice(['<', '>'])} {self.expr(1)}:")
                out += self.block(ind + "    ", depth + 1)
                if r.random() < 0.6:
                    out.append(f"{ind}else:")
                    out += self.block(ind + "    ", depth + 1)
            else:
                out.append(f"{ind}u = u * {r.uniform(0.5, 1.5):.3f}")
        return out

    def program(self) -> str:
        r = self.r
        body = "\n".join(self.block(" " * 8, 0))
        scatters = []
        for c in range(r.randint(2, 5)):
            i, j = r.randint(0, 2), r.randint(0, 2)
            scatters.append(f"        cell{c} = ti.Vector([(b0 + {i}) % {G}, (b1 + {j}) % {G}])")
            comps = r.randint(1, 3)
            for d in range(comps):
                scatters.append(f"        grid[cell{c}][{d}] += {self.expr(1)}")
            if r.random() < 0.5:
                scatters.append(f"        mass[cell{c}] += {self.expr(2)}")
        scatter = "\n".join(scatters)
        return f'''import simgrad as ti

x = ti.Vector.field(2, ti.f32, shape={N})
q = ti.Vector.field(2, ti.f64, shape={N})
kind = ti.field(ti.i32, shape={N})
grid = ti.Vector.field(3, ti.f32, shape=({G}, {G}))
mass = ti.field(ti.f64, shape=({G}, {G}))


@ti.kernel
def k():
    for p in x:
        u = x[p][0] * {r.uniform(0.5, 2):.3f}
        w = ti.cast(x[p][1], ti.f64)
        h = 0.0
        q[p] = q[p] * 0.5 + w
        if kind[p] == 1:
            u = u * 2.0
{body}
        b0 = ti.cast(ti.abs(x[p][0]) * {G}, ti.i32)
        b1 = ti.cast(ti.abs(x[p][1]) * {G}, ti.i32)
{scatter}
'''


def _run(text: str, path, width: int):
    ti.init(arch=ti.cpu, fission_lanes=width, cpu_max_num_threads=1, fast_math=False, offline_cache=False)
    spec = importlib.util.spec_from_file_location(f"fission_fuzz_{width}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rng = np.random.default_rng(0)
    mod.x.from_numpy(rng.uniform(-1, 1, (N, 2)).astype(np.float32))
    mod.q.from_numpy(rng.uniform(-1, 1, (N, 2)))
    mod.kind.from_numpy(rng.integers(0, 2, N).astype(np.int32))
    mod.k()
    mod.k()
    split = any(s.op is Op.RANGE_FOR and s.attrs.get("fission") for s in mod.k._instance_for((), "").ir.body.stmts)
    return [mod.grid.to_numpy(), mod.mass.to_numpy(), mod.q.to_numpy()], split


@pytest.mark.parametrize("chunk", range(3))
def test_random_scatter_loops_agree_bit_for_bit(tmp_path, chunk, monkeypatch):
    from simgrad.passes import fission

    monkeypatch.setattr(fission, "MIN_FLOAT_OPS_PER_SCATTER", 0)  # small programs: split them all the same
    split = 0
    for seed in range(chunk * 6, chunk * 6 + 6):
        text = _Gen(seed).program()
        path = tmp_path / f"prog{seed}.py"
        path.write_text(text)
        off, was = _run(text, path, 0)
        assert not was
        on, was = _run(text, path, 8)
        split += was
        for a, b in zip(off, on):
            np.testing.assert_array_equal(a.view(np.uint8), b.view(np.uint8), err_msg=text)
    assert split >= 4
