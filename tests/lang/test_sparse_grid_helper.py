"""ti.sparse (Taichi's sparse-grid helper): grid() is a struct field on a bitmasked node, usage() the fraction of
active cells, checked against numpy's count of the cells written."""

import numpy as np
import pytest

import simgrad as ti


@pytest.mark.parametrize("shape", [(10, 10), (4, 5, 6)])
def test_grid_usage_is_the_active_fraction(shape):
    ti.init(arch=ti.cpu)
    g = ti.sparse.grid({"pos": ti.math.vec2, "mass": ti.f32, "ids": ti.types.vector(3, ti.i32)}, shape=shape)
    assert g.shape == shape and ti.sparse.usage(g) == 0.0
    rng = np.random.default_rng(1)
    cells = {tuple(int(c) for c in rng.integers(0, shape)) for _ in range(17)}
    for c in cells:
        g[c].mass = 1.0
    g[next(iter(cells))].ids[2] = 123
    assert ti.sparse.usage(g) == pytest.approx(len(cells) / np.prod(shape), rel=1e-6)
    dense = np.zeros(shape, np.float32)
    for c in cells:
        dense[c] = 1.0
    np.testing.assert_array_equal(g.mass.to_numpy(), dense)  # inactive cells read 0, as Taichi's
    assert g[next(iter(cells))].ids[2] == 123


def test_grid_of_other_dimensions_is_refused():
    ti.init(arch=ti.cpu)
    with pytest.raises(Exception, match="Only 2D and 3D sparse grids are supported"):
        ti.sparse.grid({"m": ti.f32}, shape=(10,))
