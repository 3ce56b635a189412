"""The water renderer at reduced size: it runs headless, its loss goes down and it writes its pictures."""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_water_renderer_loss_decreases(tmp_path):
    import water_renderer

    losses, _ = water_renderer.train(iters=5, out=str(tmp_path), n=48, steps=24, lr=1.0)
    assert losses[-1] < 0.8 * losses[0]
    for name in ("loss.png", "floor.png", "target.png", "refracted_iter0000.png", "refracted_iter0005.png",
                 "water.gif"):
        assert (tmp_path / name).stat().st_size > 0, name


def test_vgg_loss_is_skipped_with_a_message(tmp_path, capsys):
    import water_renderer

    assert water_renderer.make_vgg_loss("", 1, 1e-3) is None  # not asked for: silently off
    missing = str(tmp_path / "no_such_vgg16.pth")
    assert water_renderer.make_vgg_loss(missing, 1, 1e-3) is None
    assert "VGG loss skipped" in capsys.readouterr().out


def test_external_image_loss_gradient_is_fed_back(tmp_path):
    """The path the VGG loss takes (its gradient seeds refracted.grad before the Tape), with a stand-in
    image loss computed in numpy: pull the picture toward mid grey."""
    import water_renderer

    def grey_loss(img):
        d = img - 0.5
        return 0.5 * float((d * d).mean()), (d / d.size).astype("float32"), 0

    losses, _ = water_renderer.train(iters=4, out=None, n=48, steps=24, lr=1.0, vgg=grey_loss)
    assert losses[-1] < losses[0]
