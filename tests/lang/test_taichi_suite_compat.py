"""Taichi behaviours found by running Taichi's own tests (issue 23's yardstick, second pass): each test here
failed before its fix and checks Taichi 1.7.4's observed result or numpy's."""

import numpy as np

import simgrad as ti


def test_fields_up_to_taichis_max_num_indices():
    # ti._lib.core.get_max_num_indices() is 12 in Taichi; a 12-d vector field's grouped loop sees every index
    ti.init(arch=ti.cpu)
    d = ti._lib.core.get_max_num_indices()
    assert d == 12
    x = ti.Vector.field(2, dtype=ti.i32, shape=(2,) * d)

    @ti.kernel
    def fill():
        for I in ti.grouped(x):
            x[I] += ti.Vector([I.sum(), I[0]])

    fill()
    idx = np.indices((2,) * d)
    got = x.to_numpy()
    np.testing.assert_array_equal(got[..., 0], idx.sum(axis=0))
    np.testing.assert_array_equal(got[..., 1], idx[0])
