# mypy: disable-error-code="valid-type"
"""ti.sparse: Taichi 1.7.4's sparse-grid helper, `grid` (a struct field placed on a bitmasked 2-D or 3-D node)
and `usage` (the fraction of its cells that are active), written with the public language as Taichi's is."""

import simgrad as ti


def grid(field_dict: dict, shape):
    """A struct field of `field_dict`'s members on `ti.root.bitmasked` of `shape` (2-D or 3-D), as Taichi's."""
    x = ti.Struct.field(field_dict)
    if len(shape) == 2:
        ti.root.bitmasked(ti.ij, shape).place(x)
    elif len(shape) == 3:
        ti.root.bitmasked(ti.ijk, shape).place(x)
    else:
        raise Exception("Only 2D and 3D sparse grids are supported")  # Taichi's exception and text
    return x


@ti.kernel
def usage(x: ti.template()) -> ti.f32:
    """Active cells of the grid's bitmasked node over all its cells, in [0, 1]."""
    cnt = 0
    for I in ti.grouped(x.parent()):
        if ti.is_active(x.parent(), I):
            cnt += 1
    total = 1.0
    for k in ti.static(range(len(x.shape))):
        total *= x.shape[k]
    return cnt / total


__all__ = ["grid", "usage"]
