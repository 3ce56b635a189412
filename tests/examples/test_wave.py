"""wave at reduced size: it runs headless, its loss goes down, its pictures exist."""

import importlib.util
import os

EXAMPLE = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "wave.py")


def load_wave():
    # examples/wave.py shares its name with the standard library's wave module: load it by path
    spec = importlib.util.spec_from_file_location("wave_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_wave_loss_decreases(tmp_path):
    wave = load_wave()
    losses, _ = wave.train(iters=6, out=str(tmp_path), n_grid=64, steps=64)
    assert losses[-1] < 0.5 * losses[0], losses
    for name in ("loss.png", "target.png", "optimized_final.png", "optimized.gif"):
        assert (tmp_path / name).exists(), name


def test_wave_target_pattern():
    target = load_wave().target_pattern(64)
    assert target.shape == (64, 64)
    assert abs(float(target.mean())) < 1e-6
    assert float(target.max() - target.min()) > 0.9  # both the ring and the star are drawn
