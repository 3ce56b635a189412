"""A Laplace solve on a sparse grid: seed 000's layout, a 1024^2 grid of 8^2 blocks under a pointer.

Only the blocks that touch a disk are allocated. Inside the disk, u solves the 5-point Laplace equation with
Dirichlet values on a one-cell ring around it, taken from a harmonic function g (a quadratic, so the discrete
solution is g itself: the printed error is the solver's, not the discretisation's). Conjugate gradients runs
entirely as struct-fors over the active cells (dot products are parallel sums), and the picture shows u over
the active blocks (grey: blocks never allocated) with the block grid drawn in.

    python examples/sparse_poisson.py [--n 1024] [--block 8] [--iters 2000] [--tol 1e-5] [--out DIR]
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir  # noqa: E402

import simgrad as ti  # noqa: E402


def build(n: int = 1024, block: int = 8, radius: float = 0.42):
    u, r, p, ap = (ti.field(ti.f32) for _ in range(4))
    kind = ti.field(ti.i8)  # 1: unknown (inside the disk), 2: Dirichlet ring, 0: in an allocated block, unused
    blocks = ti.root.pointer(ti.ij, n // block)
    blocks.dense(ti.ij, block).place(u, r, p, ap, kind)
    sums = ti.field(ti.f64, shape=2)
    h = 1.0 / n

    @ti.func
    def g(i, j):  # a harmonic quadratic: its 5-point Laplacian is exactly 0
        x, y = (i + 0.5) * h, (j + 0.5) * h
        return (x - 0.5) ** 2 - (y - 0.5) ** 2 + 0.8 * (x - 0.5) * (y - 0.5)

    @ti.kernel
    def setup():
        for i, j in ti.ndrange(n, n):  # writes activate exactly the blocks the disk and its ring touch
            d = ti.sqrt(((i + 0.5) * h - 0.5) ** 2 + ((j + 0.5) * h - 0.5) ** 2)
            if d < radius:
                kind[i, j] = 1
            elif d < radius + 1.5 * h:
                kind[i, j] = 2
                u[i, j] = g(i, j)

    @ti.func
    def laplacian(f: ti.template(), i, j):
        return f[i - 1, j] + f[i + 1, j] + f[i, j - 1] + f[i, j + 1] - 4.0 * f[i, j]

    @ti.kernel
    def start():
        sums[0] = 0.0
        for i, j in kind:
            if kind[i, j] == 1:
                r[i, j] = laplacian(u, i, j)  # b - A u, the ring's values on the right-hand side
                p[i, j] = r[i, j]
                sums[0] += ti.cast(r[i, j], ti.f64) ** 2

    @ti.kernel
    def apply_a():
        sums[1] = 0.0
        for i, j in kind:
            if kind[i, j] == 1:
                ap[i, j] = -laplacian(p, i, j)  # p is 0 on the ring and beyond: A acts on unknowns only
                sums[1] += ti.cast(p[i, j] * ap[i, j], ti.f64)

    @ti.kernel
    def update(alpha: ti.f32):
        sums[0] = 0.0
        for i, j in kind:
            if kind[i, j] == 1:
                u[i, j] += alpha * p[i, j]
                r[i, j] -= alpha * ap[i, j]
                sums[0] += ti.cast(r[i, j], ti.f64) ** 2

    @ti.kernel
    def direction(beta: ti.f32):
        for i, j in kind:
            if kind[i, j] == 1:
                p[i, j] = r[i, j] + beta * p[i, j]

    @ti.kernel
    def max_error() -> ti.f32:
        e = 0.0
        for i, j in kind:
            if kind[i, j] == 1:
                ti.atomic_max(e, ti.abs(u[i, j] - g(i, j)))
        return e

    def solve(iters: int, tol: float) -> tuple[int, float]:
        start()
        rs = sums[0]
        rs0 = rs
        k = 0
        while k < iters and rs > tol * tol * rs0:
            apply_a()
            alpha = rs / sums[1]
            update(alpha)
            rs, rs_old = sums[0], rs
            direction(rs / rs_old)
            k += 1
        return k, float(np.sqrt(rs / rs0))

    return dict(setup=setup, solve=solve, max_error=max_error, u=u, kind=kind, blocks=blocks)


def picture(sim, n: int, block: int, path: str) -> None:
    """u where the disk is, the ring white, unused cells of allocated blocks dark, unallocated blocks grey, and
    the block grid drawn over the allocated ones."""
    u, kind = sim["u"].to_numpy(), sim["kind"].to_numpy()
    nb = n // block
    active = kind.reshape(nb, block, nb, block).any(axis=(1, 3))  # every allocated block holds a ring or disk cell
    active_cells = np.kron(active, np.ones((block, block), bool))
    inside = kind == 1
    lo, hi = u[inside].min(), u[inside].max()
    img = np.full((n, n, 3), 0.55, np.float32)
    img[active_cells] = 0.12
    shade = np.clip((u - lo) / (hi - lo + 1e-12), 0, 1)
    img[inside] = np.stack([shade, 0.35 + 0.3 * shade, 1 - shade], -1)[inside]
    img[kind == 2] = 1.0
    edges = np.zeros((n, n), bool)
    edges[::block, :] = edges[:, ::block] = True
    img[edges & active_cells] *= 0.6
    gui = ti.GUI("sparse_poisson", res=(n, n), show_gui=False)
    gui.set_image(img)
    gui.show(path)


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1024)
    ap.add_argument("--block", type=int, default=8)
    ap.add_argument("--iters", type=int, default=2000)
    ap.add_argument("--tol", type=float, default=1e-5)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    ti.init(arch=ti.cpu)
    sim = build(args.n, args.block)
    t0 = time.time()
    sim["setup"]()
    k, rel = sim["solve"](args.iters, args.tol)
    seconds = time.time() - t0
    err = sim["max_error"]()
    use = sim["blocks"].memory_usage()
    total_blocks = (args.n // args.block) ** 2
    print(f"{k} CG iterations, relative residual {rel:.2e}, max |u - g| {err:.2e}, {seconds:.2f} s; "
          f"{use['live_blocks']} of {total_blocks} blocks allocated ({use['touched_bytes'] / 2**20:.1f} MiB)")
    out = out_dir(args.out, "sparse_poisson")
    picture(sim, args.n, args.block, os.path.join(out, "solution.png"))
    return dict(iterations=k, residual=rel, error=err, live_blocks=use["live_blocks"], total_blocks=total_blocks)


if __name__ == "__main__":
    main()
