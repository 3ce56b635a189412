"""Frame time of ti.ui 3-D scenes (issue 13): 100k particles and a 100k-triangle mesh at 1024x768.

    python benchmarks/ggui_frame.py [--frames 20] [--res 1024 768] [--particles 100000] [--triangles 100000]

A GGUI frame loop as a program writes it, headless: each frame sets the background, camera and lights,
declares the particles (a Vector field, per-particle colours) and/or the mesh (vertex and index fields,
normals inferred every frame as Taichi does), renders the scene onto the canvas and shows the window.
Reported: milliseconds per frame (median and best over ``--frames`` frames after 3 warm-up frames) for
particles only, mesh only, and both.  Taichi's GGUI needs Vulkan, so there is no taichi column: the
target is 50 ms a frame.
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
    ap.add_argument("--save", default=None, help="write the last frame of each case to <save>_<case>.png")
    args = ap.parse_args()

    ti.init(arch=ti.cpu)
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

    results = {}
    for case, flags in (("particles", (True, False)), ("mesh", (False, True)), ("both", (True, True))):
        for _ in range(3):
            frame(*flags)
            window.show()
        times = []
        for _ in range(args.frames):
            t0 = time.perf_counter()
            frame(*flags)
            window.show()
            times.append(time.perf_counter() - t0)
        if args.save:
            frame(*flags)
            window.save_image(f"{args.save}_{case}.png")
            window.show()
        ms = np.array(times) * 1e3
        results[case] = {"median_ms": round(float(np.median(ms)), 1), "best_ms": round(float(ms.min()), 1)}
        print(f"{case:10s} median {np.median(ms):6.1f} ms   best {ms.min():6.1f} ms   ({args.frames} frames, "
              f"{args.res[0]}x{args.res[1]}, {n} particles, {len(t_np)} triangles)", flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
