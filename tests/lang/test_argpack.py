"""ti.types.argpack as Taichi 1.7.4 has it: members of every parameter kind (scalars, bool, vectors, structs,
ndarrays, nested packs) passed under one name; not a struct member, not a return type."""

import numpy as np
import pytest

import simgrad as ti


def test_argpack_members_of_every_kind():
    S = ti.types.struct(a=ti.i32, c=ti.f64)
    inner_t = ti.types.argpack(a=ti.i32, b=ti.i32)
    pack_t = ti.types.argpack(k=ti.i32, flag=bool, v=ti.types.vector(3, ti.f64), s=S,
                              arr=ti.types.ndarray(dtype=ti.math.vec3, ndim=2), inner=inner_t)
    arr = ti.ndarray(dtype=ti.math.vec3, shape=(4, 4))
    arr.fill([1.0, 2.0, 3.0])

    @ti.kernel
    def f(p: pack_t) -> ti.f64:
        r = p.k * p.v[1] + p.s.c + p.s.a + p.arr[2, 3][2] + p.inner.a * p.inner.b
        if p.flag:
            r = -r
        return r

    @ti.kernel
    def write(p: pack_t):
        for i, j in p.arr:
            p.arr[i, j] = ti.Vector([i, j, p.k])

    def pack(k, flag):
        return pack_t(k=k, flag=flag, v=[1.0, 2.0, 3.0], s=S(a=5, c=0.25), arr=arr, inner=inner_t(a=3, b=4))

    assert f(pack(2, False)) == pytest.approx(2 * 2.0 + 0.25 + 5 + 3.0 + 12)
    assert f(pack(7, True)) == pytest.approx(-(7 * 2.0 + 0.25 + 5 + 3.0 + 12))
    write(pack(9, False))
    a = arr.to_numpy()
    assert a[2, 3].tolist() == [2.0, 3.0, 9.0] and a[0, 1].tolist() == [0.0, 1.0, 9.0]


def test_argpack_ndarray_member_keys_the_instantiation():
    pack_t = ti.types.argpack(x=ti.types.ndarray(), scale=ti.f32)

    @ti.kernel
    def total(p: pack_t) -> ti.f64:
        s = 0.0
        for i in p.x:
            s += p.x[i] * p.scale
        return s

    assert total(pack_t(x=np.arange(5, dtype=np.int32), scale=2.0)) == 20.0
    assert total(pack_t(x=np.full(3, 0.5, dtype=np.float64), scale=2.0)) == 3.0


def test_argpack_misuse_is_refused():
    pack_t = ti.types.argpack(a=ti.i32, b=bool)
    assert repr(pack_t) == "<ti.ArgPackType a=i32, b=u1>"
    with pytest.raises(ValueError, match="Invalid data type <ti.ArgPackType a=i32, b=u1>"):
        ti.types.struct(element=pack_t)
    with pytest.raises(ti.TaichiSyntaxError):
        @ti.kernel
        def ret(p: pack_t) -> pack_t:
            return p

    @ti.kernel
    def k(p: pack_t) -> ti.i32:
        return p.a

    with pytest.raises(ti.TaichiTypeError, match="expects a value of <ti.ArgPackType"):
        k(3)
