"""Advection on a sparse grid whose active blocks follow the smoke.

A blob of density is carried around the centre by a rotating velocity field (semi-Lagrangian, bilinear). The
density lives under `ti.root.pointer(ti.ij, n // block).dense(ti.ij, block)`: every step activates the blocks
next to any block holding density (so the blob can move into them), advects over the active cells only, and
deactivates the blocks that end up empty. The picture shows the density at several times, with the blocks
active at that moment outlined; a dense run of the same steps checks the sparse one (printed difference).

    python examples/sparse_advection.py [--n 512] [--block 8] [--steps 400] [--out DIR]
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir  # noqa: E402

import simgrad as ti  # noqa: E402


def build(n: int = 512, block: int = 8, dt: float = 0.004, dense: bool = False):
    nb = n // block
    rho, new = ti.field(ti.f32), ti.field(ti.f32)
    if dense:
        ti.root.dense(ti.ij, n).place(rho, new)
        blocks = None
    else:
        blocks = ti.root.pointer(ti.ij, nb)
        blocks.dense(ti.ij, block).place(rho, new)
    h = 1.0 / n
    eps = 1e-4

    @ti.kernel
    def seed():
        for i, j in ti.ndrange(n, n):
            x, y = (i + 0.5) * h, (j + 0.5) * h
            d2 = (x - 0.72) ** 2 + (y - 0.5) ** 2
            if d2 < 0.09**2:
                rho[i, j] = ti.exp(-d2 / (2 * 0.04**2))

    @ti.func
    def velocity(x, y):
        return ti.Vector([-(y - 0.5), x - 0.5]) * 2.0 * np.pi / 2.0  # one turn every 2 time units

    @ti.func
    def sample(i: ti.f32, j: ti.f32):
        i = ti.min(ti.max(i, 0.0), n - 1.001)
        j = ti.min(ti.max(j, 0.0), n - 1.001)
        i0, j0 = int(ti.floor(i)), int(ti.floor(j))
        fi, fj = i - i0, j - j0
        return (rho[i0, j0] * (1 - fi) * (1 - fj) + rho[i0 + 1, j0] * fi * (1 - fj)
                + rho[i0, j0 + 1] * (1 - fi) * fj + rho[i0 + 1, j0 + 1] * fi * fj)

    @ti.func
    def block_density(bi, bj):
        s = 0.0
        for di, dj in ti.ndrange(block, block):
            s += rho[bi * block + di, bj * block + dj]
        return s

    @ti.kernel
    def grow():
        """Activate the neighbours of every block that holds density."""
        for bi, bj in blocks:
            if block_density(bi, bj) > eps:
                for oi, oj in ti.static(ti.ndrange((-1, 2), (-1, 2))):
                    ni, nj = bi + oi, bj + oj
                    if 0 <= ni < nb and 0 <= nj < nb:
                        ti.activate(blocks, [ni, nj])

    @ti.kernel
    def advect():
        for i, j in rho:  # the active cells only (all cells of a dense field)
            x, y = (i + 0.5) * h, (j + 0.5) * h
            v = velocity(x, y)
            mid = ti.Vector([x, y]) - 0.5 * dt * v  # second-order back-trace
            p = ti.Vector([x, y]) - dt * velocity(mid[0], mid[1])
            new[i, j] = sample(p[0] / h - 0.5, p[1] / h - 0.5)
        for i, j in rho:
            rho[i, j] = new[i, j]

    @ti.kernel
    def shrink():
        """Deactivate the blocks left without density."""
        for bi, bj in blocks:
            if block_density(bi, bj) <= eps:
                ti.deactivate(blocks, [bi, bj])

    def step():
        if blocks is not None:
            grow()
        advect()
        if blocks is not None:
            shrink()

    return dict(seed=seed, step=step, rho=rho, blocks=blocks)


def active_blocks(sim, n: int, block: int) -> np.ndarray:
    rho = sim["rho"].to_numpy()  # zero where inactive; an active block with no density left is shrunk away
    nb = n // block
    return (np.abs(rho).reshape(nb, block, nb, block).sum(axis=(1, 3)) > 0)


def frame(rho: np.ndarray, active: np.ndarray, block: int) -> np.ndarray:
    img = np.repeat(np.clip(rho, 0, 1)[..., None], 3, axis=-1) * np.array([1.0, 0.85, 0.5], np.float32)
    edge = np.zeros((block, block), bool)
    edge[0, :] = edge[:, 0] = True
    outline = np.kron(active, edge).astype(bool)
    img[outline] = img[outline] * 0.3 + np.array([0.2, 0.6, 1.0], np.float32) * 0.7
    return img


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=512)
    ap.add_argument("--block", type=int, default=8)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    n, block = args.n, args.block
    ti.init(arch=ti.cpu)
    sim = build(n, block)
    sim["seed"]()
    shots, counts = [], []
    every = max(1, args.steps // args.frames)
    t0 = time.time()
    for s in range(args.steps + 1):
        if s % every == 0:
            active = active_blocks(sim, n, block)
            shots.append(frame(sim["rho"].to_numpy(), active, block))
            counts.append(int(active.sum()))
        if s < args.steps:
            sim["step"]()
    seconds = time.time() - t0
    sparse_rho = sim["rho"].to_numpy()
    ti.init(arch=ti.cpu)
    ref = build(n, block, dense=True)
    ref["seed"]()
    for _ in range(args.steps):
        ref["step"]()
    dense_rho = ref["rho"].to_numpy()
    diff = float(np.abs(sparse_rho - dense_rho).max())
    print(f"{args.steps} steps in {seconds:.2f} s; active blocks over time {counts} of {(n // block) ** 2}; "
          f"mass {sparse_rho.sum() / n**2:.5f} (dense {dense_rho.sum() / n**2:.5f}); max |sparse - dense| {diff:.2e}")
    out = out_dir(args.out, "sparse_advection")
    gui = ti.GUI("sparse_advection", res=(n * len(shots), n), show_gui=False)
    gui.set_image(np.concatenate(shots, axis=0))
    gui.show(os.path.join(out, "advection.png"))
    return dict(diff=diff, counts=counts, total_blocks=(n // block) ** 2, mass=float(sparse_rho.sum()),
                dense_mass=float(dense_rho.sum()))


if __name__ == "__main__":
    main()
