"""The 2-D Laplace operator of the Taichi paper: u = (4 v[i,j] - neighbours) / dx^2 over a grid.

    python examples/laplace.py

Checks the result against numpy and prints the maximum error.
"""

import numpy as np

import simgrad as ti

ti.init(arch=ti.cpu)

N = 256
dx = 1.0 / N
u = ti.field(ti.f32, shape=(N, N))
v = ti.field(ti.f32, shape=(N, N))


@ti.kernel
def laplace():
    for i, j in u:
        if 0 < i < N - 1 and 0 < j < N - 1:
            c = 1 / (dx * dx)
            u[i, j] = c * (4.0 * v[i, j] - v[i - 1, j] - v[i + 1, j] - v[i, j - 1] - v[i, j + 1])


def main():
    xs = np.linspace(0, 1, N, dtype=np.float32)
    vv = np.sin(np.pi * xs)[:, None] * np.sin(np.pi * xs)[None, :]
    v.from_numpy(vv)
    laplace()
    ref = np.zeros_like(vv)
    ref[1:-1, 1:-1] = (4 * vv[1:-1, 1:-1] - vv[:-2, 1:-1] - vv[2:, 1:-1] - vv[1:-1, :-2] - vv[1:-1, 2:]) / dx**2
    err = np.abs(u.to_numpy() - ref).max() / np.abs(ref).max()
    print(f"laplace on {N}x{N}: max relative error vs numpy {err:.2e}")
    return err


if __name__ == "__main__":
    main()
