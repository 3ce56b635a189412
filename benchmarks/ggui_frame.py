"""Frame time of ti.ui scenes (issue 13): 100k particles and a 100k-triangle mesh at 1024x768, and 2-D canvas
primitives (100k circles, 10k triangles, 10k lines).

    python benchmarks/ggui_frame.py [--frames 20] [--res 1024 768] [--particles 100000] [--triangles 100000]
                                    [--circles 100000] [--triangles2d 10000] [--lines 10000] [--only 2d|3d]

A GGUI frame loop as a program writes it, headless: each frame sets the background, camera and lights,
declares the particles (a Vector field, per-particle colours) and/or the mesh (vertex and index fields,
normals inferred every frame as Taichi does), renders the scene onto the canvas and shows the window.
Reported: milliseconds per frame (median and best over ``--frames`` frames after 3 warm-up frames) for
particles only, mesh only, and both.  Taichi's GGUI needs Vulkan, so there is no taichi column: the
target is 50 ms a frame.

The 2-D cases draw on the canvas each frame (``set_background_color``, then ``canvas.circles`` of radius
0.003 with per-vertex colours, ``canvas.triangles`` of small random triangles with per-vertex colours,
``canvas.lines`` of width 0.003), once through the window's canvas (simgrad kernels, render2d.py) and once
through the numpy rasteriser that drew them before (``ImageCanvas`` with the same unit conversions), and
force the pixels to be drawn (a headless ``show()`` alone would skip drawing).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import simgrad as ti


def sphere_mesh(n_triangles: int, radius: float, center):
    """A UV sphere with about ``n_triangles`` triangles, wound counter-clockwise seen from outside."""
    rings = max(2, int(round(np.sqrt(n_triangles / 2 / 1.25))))
    segments = max(3, int(round(n_triangles / 2 / rings)))
    theta = np.linspace(0, np.pi, rings + 1)
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    verts = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    verts = (verts * radius + np.asarray(center)).astype(np.float32)
    idx = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tris = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return verts, tris.astype(np.int32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--res", type=int, nargs=2, default=(1024, 768))
    ap.add_argument("--particles", type=int, default=100_000)
    ap.add_argument("--triangles", type=int, default=100_000)
    ap.add_argument("--circles", type=int, default=100_000)
    ap.add_argument("--triangles2d", type=int, default=10_000)
    ap.add_argument("--lines", type=int, default=10_000)
    ap.add_argument("--only", choices=("2d", "3d"), default=None)
    ap.add_argument("--save", default=None, help="write the last frame of each case to <save>_<case>.png")
    args = ap.parse_args()

    ti.init(arch=ti.cpu)
    results = {}
    if args.only != "3d":
        results.update(bench_2d(args))
    if args.only != "2d":
        results.update(bench_3d(args))
    print(json.dumps(results))


def timed(args, draw, show, label, results, note):
    """Median and best ms of ``draw(); show()`` over ``args.frames`` frames after 3 warm-up frames."""
    for _ in range(3):
        draw()
        show()
    times = []
    for _ in range(args.frames):
        t0 = time.perf_counter()
        draw()
        show()
        times.append(time.perf_counter() - t0)
    ms = np.array(times) * 1e3
    results[label] = {"median_ms": round(float(np.median(ms)), 3), "best_ms": round(float(ms.min()), 3)}
    print(f"{label:18s} median {np.median(ms):6.1f} ms   best {ms.min():6.1f} ms   ({args.frames} frames, "
          f"{args.res[0]}x{args.res[1]}, {note})", flush=True)


def bench_2d(args):
    from simgrad.gui.canvas import ImageCanvas

    W, H = args.res
    rng = np.random.default_rng(1)
    nc, nt, nl = args.circles, args.triangles2d, args.lines
    centers = rng.random((nc, 2), dtype=np.float32)
    ccolors = rng.random((nc, 3), dtype=np.float32)
    tri = (rng.random((nt, 1, 2)) + (rng.random((nt, 3, 2)) - 0.5) * 0.04).reshape(-1, 2).astype(np.float32)
    tcolors = rng.random((3 * nt, 3), dtype=np.float32)
    seg = (rng.random((nl, 1, 2)) + (rng.random((nl, 2, 2)) - 0.5) * 0.1).reshape(-1, 2).astype(np.float32)
    radius, width = 0.003, 0.003

    window = ti.ui.Window("ggui 2d benchmark", (W, H), show_window=False)
    canvas = window.get_canvas()
    ref = ImageCanvas((W, H))  # the numpy path: ti.ui units converted as the canvas did before render2d

    def kernels(circles, triangles, lines):
        def draw():
            canvas.set_background_color((1.0, 1.0, 1.0))
            if circles:
                canvas.circles(centers, radius=radius, per_vertex_color=ccolors)
            if triangles:
                canvas.triangles(tri, per_vertex_color=tcolors)
            if lines:
                canvas.lines(seg, width=width, color=(0.2, 0.3, 0.8))
            window._image.pixels()  # draw what is pending
        return draw

    def numpy_path(circles, triangles, lines):
        def draw():
            ref.clear((1.0, 1.0, 1.0))
            if circles:
                ref.circles(centers.astype(np.float64), radius * H, ccolors.astype(np.float64))
            if triangles:
                t = tri.astype(np.float64).reshape(-1, 3, 2)
                ref.triangles(t[:, 0], t[:, 1], t[:, 2], vertex_colors=tcolors.astype(np.float64).reshape(-1, 3, 3))
            if lines:
                s = seg.astype(np.float64).reshape(-1, 2, 2)
                ref.lines(s[:, 0], s[:, 1], 0.5 * width * H, np.array([0.2, 0.3, 0.8]))
            ref.pixels()
        return draw

    results: dict = {}
    cases = (("circles", (True, False, False), f"{nc} circles"),
             ("triangles2d", (False, True, False), f"{nt} triangles"),
             ("lines", (False, False, True), f"{nl} lines"),
             ("all2d", (True, True, True), "all three"))
    for case, flags, note in cases:
        timed(args, kernels(*flags), window.show, f"{case} kernels", results, note)
        timed(args, numpy_path(*flags), lambda: None, f"{case} numpy", results, note)
        if args.save:
            kernels(*flags)()
            window.save_image(f"{args.save}_{case}.png")
            window.show()
    return results


def bench_3d(args):
    rng = np.random.default_rng(0)
    n = args.particles
    centers = ti.Vector.field(3, ti.f32, n)
    colors = ti.Vector.field(3, ti.f32, n)
    centers.from_numpy(rng.random((n, 3), dtype=np.float32))
    colors.from_numpy(rng.random((n, 3), dtype=np.float32) * 0.6 + 0.3)
    v_np, t_np = sphere_mesh(args.triangles, 0.35, (0.5, 0.5, 0.5))
    verts = ti.Vector.field(3, ti.f32, len(v_np))
    indices = ti.field(ti.i32, t_np.size)
    verts.from_numpy(v_np)
    indices.from_numpy(t_np.reshape(-1))

    window = ti.ui.Window("ggui benchmark", tuple(args.res), show_window=False)
    canvas = window.get_canvas()
    scene = window.get_scene()
    camera = ti.ui.Camera()
    camera.position(0.5, 0.9, 2.6)
    camera.lookat(0.5, 0.45, 0.5)
    camera.up(0, 1, 0)

    def frame(particles: bool, mesh: bool):
        canvas.set_background_color((1.0, 1.0, 1.0))
        scene.set_camera(camera)
        scene.ambient_light((0.2, 0.2, 0.2))
        scene.point_light(pos=(2.0, 3.0, 3.0), color=(1.0, 1.0, 1.0))
        if particles:
            scene.particles(centers, radius=0.008, per_vertex_color=colors)
        if mesh:
            scene.mesh(verts, indices=indices, color=(0.3, 0.6, 0.9))
        canvas.scene(scene)

    results: dict = {}
    for case, flags in (("particles", (True, False)), ("mesh", (False, True)), ("both", (True, True))):
        timed(args, lambda flags=flags: frame(*flags), window.show, case, results,
              f"{n} particles, {len(t_np)} triangles")
        if args.save:
            frame(*flags)
            window.save_image(f"{args.save}_{case}.png")
            window.show()
    return results


if __name__ == "__main__":
    main()
