"""ti.func struct parameters are passed by value: a fresh struct local per call (issue 21: cornell_box's
`raytrace(ray: Ray)` updates `ray.color` in a loop with a break)."""

import numpy as np

import simgrad as ti


def test_struct_parameter_updated_in_a_loop_with_break():
    S = ti.types.struct(a=float, b=float)
    out = ti.field(float, 4)

    @ti.func
    def g(s: S) -> S:
        for _ in range(3):
            if s.a > 1.5:
                s.b = -1.0
                break
            s.b *= 2.0
        return s

    @ti.kernel
    def k():
        for i in out:
            s = g(S(1.0 * i, 1.0))
            out[i] = s.b

    k()
    np.testing.assert_array_equal(out.to_numpy(), [8.0, 8.0, -1.0, -1.0])


def test_struct_parameter_is_a_copy():
    S = ti.types.struct(a=float, b=float)
    out = ti.field(float, 2)

    @ti.func
    def bump(s: S):
        s.b += 1.0
        return s.b

    @ti.kernel
    def k():
        s = S(0.0, 1.0)
        if out[0] == 0.0:
            out[1] = bump(s)
        out[0] = s.b

    k()
    np.testing.assert_array_equal(out.to_numpy(), [1.0, 2.0])
