"""The device interface (runtime/device.py): the host implementation, and the CUDA one where cuda-python and
a GPU exist."""

import numpy as np
import pytest

from simgrad.runtime import device


def test_host_driver_memory_and_copies():
    d = device.HostDriver()
    p = d.alloc(64)
    assert p % 64 == 0
    a = np.arange(16, dtype=np.float32)
    d.to_device(p, a)
    b = np.zeros(16, np.float32)
    d.to_host(b, p)
    assert (a == b).all()
    d.free(p)
    with pytest.raises(device.DeviceError, match="did not allocate"):
        d.free(p)
    e0 = d.event()
    d.synchronize()
    assert d.elapsed_ms(e0, d.event()) >= 0


def test_host_driver_bad_launch_is_located():
    d = device.HostDriver()
    with pytest.raises(device.DeviceError, match="invalid launch configuration") as e:
        d.launch(None, 1, 2048, 0)
    assert "test_device.py" in str(e.value)


@pytest.mark.skipif(not device.cuda_available(), reason="no CUDA driver/device (cuda-python) on this machine")
def test_cuda_driver_roundtrip_and_oom():
    d = device.CudaDriver()
    p = d.alloc(1024)
    a = np.arange(256, dtype=np.float32)
    d.to_device(p, a)
    b = np.zeros_like(a)
    d.to_host(b, p)
    assert (a == b).all()
    d.free(p)
    with pytest.raises(device.DeviceMemoryError):
        d.alloc(1 << 50)
