"""Foreign arrays as ndarray arguments, by reference: torch tensors and any object with `__dlpack__` (JAX,
CuPy, numpy), and explicit (value, gradient) pairs. Kernels read and write the caller's memory (zero copy),
so what cannot be passed that way is refused at the user's line, never copied silently: a non-contiguous
layout (the kernel addresses elements as a dense row-major block), a dtype kernels have no type for, or
memory on another device than the program's (a CUDA tensor on arch=cpu). On arch=cuda a CUDA tensor's data
pointer is a device address kernels can take as it is, and host arrays go through a device copy made for the
launch and copied back after it (runtime/gpu_launch.py Staging, as Taichi does); DLPack's
device tuple (`__dlpack_device__`, kDLCUDA = 2) says where an array lives without importing its library."""

from __future__ import annotations

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import SimgradTypeError, SimgradValueError, caller_loc

# DLPack device types (dlpack.h DLDeviceType)
DL_CPU, DL_CUDA, DL_CUDA_HOST, DL_CUDA_MANAGED = 1, 2, 3, 13


def is_torch(a) -> bool:
    """Whether `a` is a torch tensor (checked without importing torch)."""
    return type(a).__module__.startswith("torch") and hasattr(a, "data_ptr") and hasattr(a, "is_contiguous")


def is_foreign(a) -> bool:
    """Whether `a` is an array this module passes: a torch tensor, a GradPair, or a non-numpy object with
    `__dlpack__` (numpy arrays and ti.ndarray objects are the ndarray kind's own)."""
    if isinstance(a, np.ndarray) or hasattr(a, "_ndarray_data"):
        return False
    return isinstance(a, GradPair) or is_torch(a) or hasattr(a, "__dlpack__")


class GradPair:
    """`ti.ad.with_grad(value, grad)`: an ndarray argument whose gradient array is given explicitly (two
    arrays of one shape and dtype: numpy, torch or DLPack). Kernels see `grad` as the argument's gradient:
    `kernel.grad` and a Tape accumulate into it, whatever `value.grad` is."""

    def __init__(self, value, grad):
        for name, x in (("value", value), ("grad", grad)):
            if isinstance(x, GradPair) or not (isinstance(x, np.ndarray) or is_torch(x) or hasattr(x, "__dlpack__")):
                raise SimgradTypeError(f"ti.ad.with_grad: {name} must be a numpy array, a torch tensor or an object "
                                       f"with __dlpack__, got {type(x).__name__}", caller_loc())
        vt, gt = array_dtype(value), array_dtype(grad)
        if not vt.is_float:
            raise SimgradTypeError(f"ti.ad.with_grad: gradients need a floating-point array, got {vt}", caller_loc())
        if vt is not gt or tuple(value.shape) != tuple(grad.shape):
            raise SimgradValueError(f"ti.ad.with_grad: the gradient must have the value's shape and dtype: value "
                                    f"{tuple(value.shape)} {vt}, grad {tuple(grad.shape)} {gt}", caller_loc())
        self.value, self.grad = value, grad
        self.shape, self.dtype = tuple(value.shape), value.dtype
        self.requires_grad = True


def described(a):
    """What shape and dtype are read from at compile time: the tensor itself, a pair's value, or a numpy view
    of a DLPack array."""
    if isinstance(a, GradPair):
        a = a.value
    if is_torch(a) or isinstance(a, np.ndarray):
        return a
    return _dlpack_view(a, "argument")


def _torch_types() -> dict:
    import torch

    m = {torch.float32: dt.f32, torch.float64: dt.f64, torch.float16: dt.f16, torch.int8: dt.i8, torch.int16: dt.i16,
         torch.int32: dt.i32, torch.int64: dt.i64, torch.uint8: dt.u8}
    for name, t in (("uint16", dt.u16), ("uint32", dt.u32), ("uint64", dt.u64)):
        if hasattr(torch, name):
            m[getattr(torch, name)] = t
    return m


_TORCH: dict = {}


def array_dtype(a) -> dt.DataType:
    """The element type of an array argument (numpy, torch, DLPack, GradPair); a located error when kernels
    have no such type (bool, complex, bfloat16)."""
    if isinstance(a, GradPair):
        a = a.value
    if is_torch(a):
        if not _TORCH:
            _TORCH.update(_torch_types())
        t = _TORCH.get(a.dtype)
        if t is None:
            raise SimgradTypeError(f"a tensor of {a.dtype} cannot be a kernel argument (kernels take f16, f32, f64, "
                                   "i8-i64 and u8-u64 arrays); convert it explicitly, e.g. t.float()", caller_loc())
        return t
    arr = a if isinstance(a, np.ndarray) else _dlpack_view(a, "argument")
    try:
        return dt.from_numpy(arr.dtype)
    except (KeyError, TypeError, ValueError):
        raise SimgradTypeError(f"an array of {arr.dtype} cannot be a kernel argument (kernels take f16, f32, f64, "
                               "i8-i64 and u8-u64 arrays)", caller_loc()) from None


def _dlpack_view(a, param: str) -> np.ndarray:
    """A numpy view of a host array exported through DLPack (zero copy); other devices are refused."""
    dev = a.__dlpack_device__()[0] if hasattr(a, "__dlpack_device__") else DL_CPU
    if dev not in (DL_CPU, DL_CUDA_HOST):
        raise SimgradTypeError(f"array argument '{param}' lives on DLPack device {dev}, not in host memory: the "
                               "program runs on the CPU (copy it to the host explicitly)", caller_loc())
    try:
        return np.from_dlpack(a)
    except (TypeError, BufferError, RuntimeError) as e:
        raise SimgradTypeError(f"array argument '{param}' could not be exported through DLPack: {e}",
                               caller_loc()) from None


def tensor_info(a, kernel: str, param: str, stage=None):
    """(base address, shape) of a torch tensor or DLPack array argument, checked: C-contiguous, and in the
    program's memory. `stage` (the program runs on an asynchronous GPU; runtime/gpu_launch.py Staging): CUDA
    tensors are taken as they are, host arrays and tensors through their device copy, as Taichi copies external
    arrays in and out; without it (the CPU) host memory only."""
    on_device = stage is not None
    if is_torch(a):
        dev = a.device.type
        if dev != "cpu" and not (on_device and dev == "cuda"):
            where = "the program runs on the CPU" if not on_device else "arch=cuda takes CUDA and host tensors"
            raise SimgradTypeError(f"kernel {kernel}: tensor argument '{param}' is on device {a.device}: {where} "
                                   f"(move it explicitly: .to(...))", caller_loc())
        if not a.is_contiguous():
            raise SimgradValueError(f"kernel {kernel}: Non contiguous tensors are not supported: argument "
                                    f"'{param}' has strides {a.stride()} for shape {tuple(a.shape)}; pass "
                                    "t.contiguous() (a copy: write results back yourself)", caller_loc())
        if a.requires_grad and a.grad is None:  # as Taichi: every tensor that requires grad gets one at launch
            a.grad = a.new_zeros(a.shape)
        if on_device and dev == "cpu":  # its memory as a numpy array (shared), staged
            return stage(a.detach().numpy()), tuple(a.shape)
        return a.data_ptr(), tuple(a.shape)
    if isinstance(a, np.ndarray):
        arr = a
    elif on_device and hasattr(a, "__cuda_array_interface__"):
        cai = a.__cuda_array_interface__
        if cai.get("strides") is not None and \
                tuple(cai["strides"]) != tuple(np.empty(cai["shape"], np.dtype(cai["typestr"])).strides):
            raise SimgradValueError(f"kernel {kernel}: Non contiguous arrays are not supported (argument "
                                    f"'{param}')", caller_loc())
        return cai["data"][0], tuple(cai["shape"])
    else:
        arr = _dlpack_view(a, param)
    if not arr.flags.c_contiguous:
        raise SimgradValueError(f"kernel {kernel}: Non contiguous arrays are not supported: argument '{param}' has "
                                f"strides {arr.strides} for shape {arr.shape}; pass a C-contiguous copy",
                                caller_loc())
    if on_device:
        return stage(arr), arr.shape
    return arr.ctypes.data, arr.shape


def tensor_grad_info(a, shape, kernel: str, param: str, stage=None) -> int:
    """The base address of the gradient of a tensor argument: a GradPair's `grad`, else the tensor's `.grad`
    (tensor_info made it zero when it had none yet, as Taichi does); its shape must be the argument's."""
    if isinstance(a, GradPair):
        grad = a.grad
    else:
        grad = getattr(a, "grad", None)  # made by tensor_info for a tensor that requires grad
        if grad is None:
            raise SimgradTypeError(f"kernel {kernel}: argument '{param}' has no gradient (a tensor that requires "
                                   "grad, or ti.ad.with_grad(value, grad))", caller_loc())
    ptr, gshape = tensor_info(grad, kernel, param + ".grad", stage)
    if tuple(gshape) != tuple(shape):
        raise SimgradTypeError(f"kernel {kernel}: the gradient of '{param}' has shape {tuple(gshape)}, its array "
                               f"{tuple(shape)}", caller_loc())
    return ptr
