# mypy: disable-error-code="valid-type"
"""Matrix-free Krylov solvers over simgrad fields: LinearOperator (a kernel computing A @ v), MatrixFreeCG and
MatrixFreeBICGSTAB. Every vector operation is a simgrad kernel (the dot products are parallel reductions in
the fields' dtype), so the iterations run natively; only the scalar recurrences are Python.

The work fields (residual, directions, products) are made once per program, shape and dtype and reused by
later solves, as are the compiled kernels (template parameters: one instantiation per set of fields)."""

from math import sqrt

import simgrad as ti
from simgrad import dtypes as dt
from simgrad.errors import SimgradRuntimeError, SimgradTypeError, caller_loc


class LinearOperator:
    """A linear operator given by a kernel `matvec_kernel(v, Av)` that writes A @ v into Av (both fields of
    the solve's shape, passed as ti.template() arguments)."""

    def __init__(self, matvec_kernel):
        self._matvec = matvec_kernel

    def matvec(self, x, Ax) -> None:
        if x.shape != Ax.shape:
            raise SimgradRuntimeError(f"Dimension mismatch x.shape{x.shape} != Ax.shape{Ax.shape}.", caller_loc())
        self._matvec(x, Ax)


_KERNELS: dict = {}


def _kernels(t: dt.DataType) -> dict:
    """The vector kernels of one dtype (made once: the kernel cache keys them by the dtype they close over)."""
    if t in _KERNELS:
        return _KERNELS[t]

    @ti.kernel
    def dot(u: ti.template(), v: ti.template()) -> t:
        acc = ti.cast(0, t)
        for I in ti.grouped(u):
            acc += u[I] * v[I]
        return acc

    @ti.kernel
    def residual(b: ti.template(), Ax: ti.template(), r: ti.template()):
        for I in ti.grouped(r):
            r[I] = b[I] - Ax[I]

    @ti.kernel
    def assign(src: ti.template(), dst: ti.template()):
        for I in ti.grouped(dst):
            dst[I] = src[I]

    @ti.kernel
    def cg_step(alpha: t, x: ti.template(), p: ti.template(), r: ti.template(), Ap: ti.template()):
        for I in ti.grouped(x):  # x += alpha p, r -= alpha A p
            x[I] += alpha * p[I]
            r[I] -= alpha * Ap[I]

    @ti.kernel
    def cg_direction(beta: t, r: ti.template(), p: ti.template()):
        for I in ti.grouped(p):
            p[I] = r[I] + beta * p[I]

    @ti.kernel
    def bicg_direction(beta: t, omega: t, r: ti.template(), p: ti.template(), v: ti.template()):
        for I in ti.grouped(p):
            p[I] = r[I] + beta * (p[I] - omega * v[I])

    @ti.kernel
    def bicg_half(alpha: t, r: ti.template(), v: ti.template(), s: ti.template()):
        for I in ti.grouped(s):
            s[I] = r[I] - alpha * v[I]

    @ti.kernel
    def bicg_step(alpha: t, omega: t, x: ti.template(), p: ti.template(), s: ti.template(), tv: ti.template(),
                  r: ti.template()):
        for I in ti.grouped(x):  # x += alpha p + omega s, r = s - omega t
            x[I] += alpha * p[I] + omega * s[I]
            r[I] = s[I] - omega * tv[I]

    ks = dict(dot=dot, residual=residual, assign=assign, cg_step=cg_step, cg_direction=cg_direction,
              bicg_direction=bicg_direction, bicg_half=bicg_half, bicg_step=bicg_step)
    _KERNELS[t] = ks
    return ks


_WORK: dict = {}


def _work(shape: tuple, t: dt.DataType, count: int) -> list:
    """`count` work fields of this shape and dtype, kept for later solves of the same program."""
    from simgrad.lang.program import get_program

    prog = get_program()
    key = (shape, t.name, count)
    owner = _WORK.get("program")
    if owner is not prog or _WORK.get("generation") != prog.generation:
        _WORK.clear()
        _WORK.update(program=prog, generation=prog.generation)
    if key not in _WORK:
        _WORK[key] = [ti.field(t, shape=shape) for _ in range(count)]
    return _WORK[key]


def _check(name: str, b, x) -> dt.DataType:
    if getattr(b, "dtype", None) != getattr(x, "dtype", None):
        raise SimgradTypeError(f"Dtype mismatch b.dtype({getattr(b, 'dtype', None)}) != "
                               f"x.dtype({getattr(x, 'dtype', None)}).", caller_loc())
    if b.dtype not in (dt.f32, dt.f64):
        raise SimgradTypeError(f"Not supported dtype: {b.dtype}", caller_loc())
    if b.shape != x.shape:
        raise SimgradRuntimeError(f"Dimension mismatch b.shape{b.shape} != x.shape{x.shape}.", caller_loc())
    if not 1 <= len(b.shape) <= 3:
        raise SimgradRuntimeError(f"{name} only support 1D, 2D, 3D inputs; your inputs is {len(b.shape)}-D.",
                                  caller_loc())
    return b.dtype


def MatrixFreeCG(A, b, x, tol=1e-6, maxiter=5000, quiet=True) -> bool:
    """Conjugate gradients for A x = b, A a symmetric positive definite LinearOperator; b and x are scalar
    fields of one shape and dtype (f32/f64), x the initial guess, overwritten with the solution. Stops when
    |r| < tol or after maxiter iterations. Returns what Taichi's returns: whether |r|² < tol at the end."""
    t = _check("MatrixFreeCG", b, x)
    k = _kernels(t)
    r, p, Ap, Ax = _work(tuple(b.shape), t, 4)
    A._matvec(x, Ax)
    k["residual"](b, Ax, r)
    k["assign"](r, p)
    rr = k["dot"](r, r)
    if not quiet:
        print(f">>> Initial residual = {rr:e}")
    if sqrt(rr) >= tol:
        for i in range(maxiter):
            A._matvec(p, Ap)
            alpha = rr / k["dot"](p, Ap)
            k["cg_step"](alpha, x, p, r, Ap)
            rr_new = k["dot"](r, r)
            if sqrt(rr_new) < tol:
                rr = rr_new
                if not quiet:
                    print(f">>> Conjugate Gradient method converged.\n>>> #iterations {i}")
                break
            k["cg_direction"](rr_new / rr, r, p)
            rr = rr_new
            if not quiet:
                print(f">>> Iter = {i + 1:4}, Residual = {sqrt(rr):e}")
    ok = rr < tol
    if not ok and not quiet:
        print(f">>> Conjugate Gradient method failed to converge in {maxiter} iterations: Residual = "
              f"{sqrt(rr):e}")
    return ok


def MatrixFreeBICGSTAB(A, b, x, tol=1e-6, maxiter=5000, quiet=True) -> bool:
    """BiCGSTAB for A x = b, A any nonsingular LinearOperator; arguments and result as MatrixFreeCG."""
    t = _check("MatrixFreeBICGSTAB", b, x)
    k = _kernels(t)
    r, r0, p, v, s, tv, Ax = _work(tuple(b.shape), t, 7)
    A._matvec(x, Ax)
    k["residual"](b, Ax, r)
    k["assign"](r, r0)
    rr = k["dot"](r, r)
    ok = True
    if not quiet:
        print(f">>> Initial residual = {rr:e}")
    if sqrt(rr) >= tol:
        rho_old = alpha = omega = 1.0
        for i in range(maxiter):
            rho = k["dot"](r, r0)
            if rho == 0.0:
                if not quiet:
                    print(">>> BICGSTAB failed because r@r_tld = 0.")
                ok = False
                break
            if i == 0:
                k["assign"](r, p)
            else:
                k["bicg_direction"]((rho / rho_old) * (alpha / omega), omega, r, p, v)
            A._matvec(p, v)
            alpha = rho / k["dot"](r0, v)
            k["bicg_half"](alpha, r, v, s)
            A._matvec(s, tv)
            tt = k["dot"](tv, tv)
            omega = k["dot"](tv, s) / (tt if tt != 0.0 else 1e-16)
            k["bicg_step"](alpha, omega, x, p, s, tv, r)
            rr = k["dot"](r, r)
            if not quiet:
                print(f">>> Iter = {i + 1:4}, Residual = {sqrt(rr):e}")
            if sqrt(rr) < tol:
                if not quiet:
                    print(f">>> BICGSTAB method converged at #iterations {i}")
                break
            rho_old = rho
    if rr >= tol:
        if not quiet:
            print(f">>> BICGSTAB failed to converge in {maxiter} iterations: Residual = {sqrt(rr):e}")
        ok = False
    return ok
