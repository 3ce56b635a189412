"""A CPU-only stand-in for Taichi's tests/test_utils.py, written for the simgrad run of Taichi's test files.

`test(arch=..., exclude=..., require=..., **options)` parametrises a test with (ti.cpu, options) exactly when
Taichi's would run it on the CPU; the upstream conftest then calls ti.init(arch=ti.cpu, **options)."""

import os
import tempfile

import pytest
import taichi as ti

_CPU_NAMES = ("cpu", "x64", "arm64")


def _is_cpu(a) -> bool:
    return getattr(a, "name", str(a)) in _CPU_NAMES or a in (ti.cpu, ti.x64, ti.arm64)


def _as_list(v):
    if v is None:
        return []
    return list(v) if isinstance(v, (list, tuple)) else [v]


def test(arch=None, exclude=None, require=None, **options):
    archs = _as_list(arch)
    runs_on_cpu = not archs or any(_is_cpu(a) for a in archs)
    excluded = any(_is_cpu(e if not isinstance(e, (list, tuple)) else e[0]) and
                   (not isinstance(e, (list, tuple)) or len(e) == 1 or e[1] == "Linux")
                   for e in _as_list(exclude))

    def decorator(func):
        func.__ti_test__ = True
        if not runs_on_cpu or excluded:
            return pytest.mark.skip(reason="not a CPU test in Taichi's own suite")(func)
        return pytest.mark.parametrize("req_arch,req_options", [(ti.cpu, dict(options))], ids=["arch=x64"])(func)

    return decorator


def approx(expected, **kwargs):
    if isinstance(expected, bool):
        return expected
    return pytest.approx(expected, **kwargs)


def allclose(x, y, **kwargs):
    return x == approx(y, **kwargs)


def get_rel_eps():
    return 1e-6


def mkdir_p(dir_path):
    """Taichi's test_utils.mkdir_p: `mkdir -p`."""
    os.makedirs(dir_path, exist_ok=True)


def make_temp_file(*args, **kwargs):
    fd, name = tempfile.mkstemp(*args, **kwargs)
    os.close(fd)
    return name


def expected_archs():
    return [ti.cpu]


def torch_op(*, output_shapes=((1,),)):
    """Taichi's helper: a kernel over (inputs..., outputs...) ndarrays as a torch.autograd.Function whose outputs
    are f64 zeros made per call and whose backward runs kernel.grad with the outputs' .grad set to the incoming
    gradients (the inputs' .grad zeroed first; it is what the adjoint accumulates into)."""
    import torch

    def wrap(kernel):
        class Op(torch.autograd.Function):
            @staticmethod
            def forward(ctx, *inputs):
                outputs = tuple(torch.zeros(s, dtype=torch.double, requires_grad=True) for s in output_shapes)
                kernel(*inputs, *outputs)
                ctx.save_for_backward(*inputs, *outputs)
                return outputs

            @staticmethod
            def backward(ctx, *grads):
                saved = ctx.saved_tensors
                inputs, outputs = saved[:len(saved) - len(grads)], saved[len(saved) - len(grads):]
                for x in inputs:
                    x.grad.fill_(0)
                for o, g in zip(outputs, grads):
                    o.grad = g
                kernel.grad(*inputs, *outputs)
                return tuple(x.grad for x in inputs)

        return lambda *args, **kwargs: Op.apply(*args, **kwargs)

    return wrap
