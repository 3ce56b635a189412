"""Julia-set fractal (the Taichi hello-world): a parallel loop over pixels with a while loop inside.

    python examples/fractal.py [--out DIR] [--frames N]
"""

import argparse
import os

import simgrad as ti

ti.init(arch=ti.cpu)

n = 320
pixels = ti.field(dtype=float, shape=(n * 2, n))


@ti.func
def complex_sqr(z):
    return ti.Vector([z[0] ** 2 - z[1] ** 2, z[1] * z[0] * 2])


@ti.kernel
def paint(t: float):
    for i, j in pixels:  # parallel over all pixels
        c = ti.Vector([-0.8, ti.cos(t) * 0.2])
        z = ti.Vector([i / n - 1, j / n - 0.5]) * 2
        iterations = 0
        while z.norm() < 20 and iterations < 50:
            z = complex_sqr(z) + c
            iterations += 1
        pixels[i, j] = 1 - iterations * 0.02


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="out/fractal")
    parser.add_argument("--frames", type=int, default=1)
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    gui = ti.GUI("Julia Set", res=(n * 2, n), show_gui=False)
    for frame in range(args.frames):
        paint(frame * 0.03)
        gui.set_image(pixels)
        gui.show(os.path.join(args.out, f"fractal_{frame:04d}.png"))
    print(f"wrote {args.frames} frame(s) to {args.out}")


if __name__ == "__main__":
    main()
