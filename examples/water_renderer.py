"""Differentiable water renderer (DiffTaichi's water_renderer experiment, written from the paper).

A square pool of n x n cells has a background picture on its floor (made locally with Pillow). An initial
water height field evolves by the 2-D wave equation (explicit finite differences, fixed boundary, Courant
number 1/sqrt(3)) for `steps` steps; the last surface is shaded by refraction: each pixel shows the
floor displaced against the surface slope (depth * slope pixels, the small-angle form of Snell's law),
sampled bilinearly. We optimise the *initial height field* so that the refracted picture matches a
target picture, which is rendered the same way from a reference height field (three drops). The loss is
the mean squared difference of the images (L2).

With `--vgg-weights PATH` (a torchvision VGG16 state dict) the loss also includes the paper's experiment:
the cross entropy of VGG16's prediction on the centre 224 x 224 crop toward an ImageNet class
(`--vgg-class`, 1 = goldfish as in the paper), computed in PyTorch and fed back as the gradient of the
refracted image. When torch/torchvision or the weights file are missing, a message says so and only the
L2 loss is used. (The weights are never downloaded.)

Sizes: the paper's (256 x 256 cells, 256 wave steps, refraction depth 2 pixels per unit slope); about
1.5 s per iteration here, mostly the backward pass through the 256 wave steps. 60 iterations by default
(the paper's VGG run used 10).

    python examples/water_renderer.py [--iters 60] [--out out/water_renderer] [--vgg-weights vgg16.pth]
"""

import contextlib
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32


def background_image(n: int) -> np.ndarray:
    """A colourful floor picture, (n, n, 3) floats indexed [x, y] with y up."""
    from PIL import Image, ImageDraw, ImageFilter, ImageFont

    s = n / 256
    img = Image.new("RGB", (n, n))
    draw = ImageDraw.Draw(img)
    for r in range(n):  # a warm-to-cool vertical gradient
        t = r / max(n - 1, 1)
        draw.line([(0, r), (n, r)], fill=(int(240 - 150 * t), int(190 - 40 * t), int(90 + 140 * t)))
    tile = max(2, int(32 * s))
    for a in range(0, n, tile):  # a light checkerboard of tiles
        for b in range(0, n, tile):
            if (a // tile + b // tile) % 2 == 0:
                draw.rectangle([a, b, a + tile - 1, b + tile - 1], fill=None, outline=(255, 255, 255),
                               width=max(1, int(2 * s)))
    for k, (cx, cy, rad, col) in enumerate([(0.25, 0.3, 0.12, (200, 40, 60)), (0.72, 0.25, 0.09, (30, 120, 60)),
                                             (0.7, 0.72, 0.14, (40, 60, 170))]):
        bbox = [(cx - rad) * n, (cy - rad) * n, (cx + rad) * n, (cy + rad) * n]
        draw.ellipse(bbox, fill=col, outline=(255, 255, 255), width=max(1, int((2 + k) * s)))
    font = ImageFont.load_default(size=max(6, int(40 * s)))
    draw.text((n / 2, n * 0.55), "simgrad", font=font, fill=(20, 20, 20), anchor="mm",
              stroke_width=max(0, int(2 * s)), stroke_fill=(250, 250, 250))
    img = img.filter(ImageFilter.GaussianBlur(radius=max(0.5, 1.2 * s)))
    rows = np.asarray(img, dtype=np.float32) / 255.0
    return np.ascontiguousarray(rows[::-1].transpose(1, 0, 2))


def reference_height(n: int, amplitude: float = 0.4) -> np.ndarray:
    """Three Gaussian drops: the initial surface the target picture is rendered from."""
    c = (np.arange(n) + 0.5) / n
    x, y = np.meshgrid(c, c, indexing="ij")
    h = np.zeros((n, n))
    for cx, cy, w, a in [(0.5, 0.5, 0.03, 1.0), (0.3, 0.7, 0.02, -0.7), (0.75, 0.35, 0.025, 0.8)]:
        h += a * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * w * w))
    return (amplitude * h).astype(np.float32)


def build(n: int = 256, steps: int = 256, depth: float = 2.0):
    """Fields and kernels of the wave simulation and the refraction shader; returns a namespace."""
    courant2 = 1.0 / 3.0  # (c dt / dx)^2
    initial = ti.field(real, shape=(n, n), needs_grad=True)
    h = ti.field(real, shape=(steps, n, n), needs_grad=True)  # every surface, for the backward pass
    slope = ti.Vector.field(2, real, shape=(n, n), needs_grad=True)
    floor_img = ti.Vector.field(3, real, shape=(n, n))
    refracted = ti.Vector.field(3, real, shape=(n, n), needs_grad=True)
    target = ti.Vector.field(3, real, shape=(n, n))
    loss = ti.field(real, shape=(), needs_grad=True)

    @ti.kernel
    def start():
        for i, j in initial:  # still water: the first two surfaces are equal
            h[0, i, j] = initial[i, j]
            h[1, i, j] = initial[i, j]

    @ti.kernel
    def wave(t: ti.i32):
        for i, j in ti.ndrange((1, n - 1), (1, n - 1)):
            lap = h[t - 1, i + 1, j] + h[t - 1, i - 1, j] + h[t - 1, i, j + 1] + h[t - 1, i, j - 1] - 4 * h[t - 1, i, j]
            h[t, i, j] = 2 * h[t - 1, i, j] - h[t - 2, i, j] + courant2 * lap

    @ti.kernel
    def surface_slope(t: ti.i32):
        for i, j in ti.ndrange((1, n - 1), (1, n - 1)):
            slope[i, j] = 0.5 * n * ti.Vector([h[t, i + 1, j] - h[t, i - 1, j], h[t, i, j + 1] - h[t, i, j - 1]])

    @ti.kernel
    def refract():
        for i, j in refracted:
            # where the refracted view ray meets the floor, in pixels, kept inside the picture
            x = ti.min(ti.max(i - depth * slope[i, j][0], 0.0), n - 1.001)
            y = ti.min(ti.max(j - depth * slope[i, j][1], 0.0), n - 1.001)
            i0 = ti.cast(ti.floor(x), ti.i32)
            j0 = ti.cast(ti.floor(y), ti.i32)
            fx = x - i0
            fy = y - j0
            refracted[i, j] = (1 - fx) * ((1 - fy) * floor_img[i0, j0] + fy * floor_img[i0, j0 + 1]) + fx * (
                (1 - fy) * floor_img[i0 + 1, j0] + fy * floor_img[i0 + 1, j0 + 1])

    @ti.kernel
    def image_loss():
        for i, j in refracted:
            d = refracted[i, j] - target[i, j]
            loss[None] += d.dot(d) * (1.0 / (3 * n * n))

    @ti.kernel
    def descend(lr: real):
        for i, j in initial:
            initial[i, j] -= lr * initial.grad[i, j]

    def forward():
        start()
        for t in range(2, steps):
            wave(t)
        surface_slope(steps - 1)
        refract()
        image_loss()

    def setup():
        floor_img.from_numpy(background_image(n))
        initial.from_numpy(reference_height(n))
        forward()
        target.from_numpy(refracted.to_numpy())
        initial.fill(0)

    return type("Water", (), dict(locals()))


class VGGLoss:
    """Cross entropy of torchvision's VGG16 toward one ImageNet class, on the centre 224 x 224 crop."""

    def __init__(self, weights: str, label: int, scale: float):
        import torch
        import torchvision

        self.torch = torch
        self.model = torchvision.models.vgg16(weights=None)
        self.model.load_state_dict(torch.load(weights, map_location="cpu"))
        self.model.eval()
        for prm in self.model.parameters():
            prm.requires_grad_(False)
        self.label = label
        self.scale = scale
        self.mean = torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1)
        self.std = torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1)

    def __call__(self, img: np.ndarray):
        """img: (n, n, 3) in [x, y] layout. Returns (scaled loss, scaled d loss / d img)."""
        torch = self.torch
        n = img.shape[0]
        o = max(0, (n - 224) // 2)
        rows = torch.tensor(np.ascontiguousarray(img.transpose(1, 0, 2)[::-1]), requires_grad=True)
        crop = rows[o:o + 224, o:o + 224].permute(2, 0, 1)[None]
        logits = self.model((crop - self.mean) / self.std)
        ce = torch.nn.functional.cross_entropy(logits, torch.tensor([self.label]))
        ce.backward()
        grad = rows.grad.numpy()[::-1].transpose(1, 0, 2)
        top = int(logits.argmax())
        return self.scale * float(ce), self.scale * np.ascontiguousarray(grad, dtype=np.float32), top


def make_vgg_loss(weights: str | None, label: int, scale: float):
    """The VGG16 loss, or None (with a message saying why) when it cannot be used."""
    if not weights:
        return None
    try:
        import torch  # noqa: F401
        import torchvision  # noqa: F401
    except ImportError as exc:
        print(f"water_renderer: VGG loss skipped: {exc.name} is not installed (pip install torch torchvision); "
              "optimising the L2 image loss only")
        return None
    if not os.path.isfile(weights):
        print(f"water_renderer: VGG loss skipped: no weights file at {weights!r} (a torchvision VGG16 state dict); "
              "optimising the L2 image loss only")
        return None
    return VGGLoss(weights, label, scale)


def train(iters: int, out: str | None, n: int = 256, steps: int = 256, lr: float = 5.0, vgg=None,
          frames: bool = True):
    """Optimise the initial height field; returns (losses, seconds per iteration)."""
    w = build(n, steps)
    w.setup()
    losses = []
    snapshots = {}
    t0 = time.time()
    for it in progress(iters, "water_renderer"):
        if vgg is None:
            with ti.ad.Tape(loss=w.loss):
                w.forward()
            total = float(w.loss[None])
        else:
            # the VGG gradient needs the image first: render, ask PyTorch, then seed the refracted image's
            # gradient with it and let the Tape add the L2 part (Python-scope writes stay outside the Tape)
            w.loss[None] = 0
            w.forward()
            vgg_loss, vgg_grad, top = vgg(w.refracted.to_numpy())
            ti.ad.clear_all_gradients()
            w.refracted.grad.from_numpy(vgg_grad)
            with ti.ad.Tape(loss=w.loss, clear_gradients=False):
                w.forward()
            total = float(w.loss[None]) + vgg_loss
            print(f"iteration {it}: L2 {float(w.loss[None]):.5f}, VGG {vgg_loss:.4f}, VGG's top class {top}")
        losses.append(total)
        if out is not None and it in (0, iters // 2):
            snapshots[it] = w.refracted.to_numpy()
        w.descend(lr)
    seconds = (time.time() - t0) / max(iters, 1)
    if out is not None:
        os.makedirs(out, exist_ok=True)
        save_pictures(w, out, losses, snapshots, frames)
    return losses, seconds


def save_pictures(w, out, losses, snapshots, frames=True):
    plot_losses(losses, os.path.join(out, "loss.png"), "water_renderer: image loss")
    w.forward()
    snapshots[len(losses)] = w.refracted.to_numpy()
    ti.tools.imwrite(w.floor_img.to_numpy(), os.path.join(out, "floor.png"))
    ti.tools.imwrite(np.clip(w.target.to_numpy(), 0, 1), os.path.join(out, "target.png"))
    for it, img in snapshots.items():
        ti.tools.imwrite(np.clip(img, 0, 1), os.path.join(out, f"refracted_iter{it:04d}.png"))
    h0 = w.initial.to_numpy()
    ti.tools.imwrite(0.5 + 0.5 * h0 / max(float(np.abs(h0).max()), 1e-9), os.path.join(out, "initial_height.png"))
    if frames:  # the optimised surface evolving, shaded
        video = ti.tools.VideoManager(out, video_filename="water", framerate=12, automatic_build=False)
        for t in range(2, w.steps, max(1, w.steps // 24)):
            w.surface_slope(t)
            w.refract()
            video.write_frame(np.clip(w.refracted.to_numpy(), 0, 1))
        video.make_video(mp4=False)
        video.clean_frames()  # keep the GIF, not its frame PNGs
        with contextlib.suppress(OSError):  # not empty: other files are there
            os.rmdir(video.get_frame_directory())


def main():
    args = parse_args("Optimise a water height field so that the refracted floor matches a target picture",
                      iters=60, n=256, steps=256, lr=5.0, vgg_weights="", vgg_class=1, vgg_scale=1e-3)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "water_renderer")
    vgg = make_vgg_loss(args.vgg_weights, args.vgg_class, args.vgg_scale)
    losses, sec = train(args.iters, out, n=args.n, steps=args.steps, lr=args.lr, vgg=vgg)
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} in {len(losses)} iterations ({sec:.3f} s/iteration); "
          f"pictures in {out}")


if __name__ == "__main__":
    main()
