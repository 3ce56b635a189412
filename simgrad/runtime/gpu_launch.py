"""The launcher of a kernel on a device (arch=cuda: the GPU through cuda-python, or the simulated GPU).

The arguments are packed into the host context exactly as on the CPU (runtime/launch.py); a launch then copies
the context to the device, runs the kernel's segments in order (codegen/nvptx.py `Launch`: grid, block), and,
when the kernel returns values or can report an error, waits for the device and reads the return words back.
On an asynchronous device (the GPU) every launch waits for now: fields live in managed memory that Python-scope
access reads directly, and that access does not synchronize by itself yet (the next step: launches stay
asynchronous and field access, ti.sync() and the next waiting launch meet the device)."""

from __future__ import annotations

from typing import Any

import numpy as np

from simgrad.errors import SimgradNotSupportedError, caller_loc
from simgrad.runtime.abi import CTX_TAPE, CTX_TAPE_CAP, CTX_TAPE_SERIAL
from simgrad.runtime.device import Device, saturating_grid
from simgrad.runtime.launch import Launcher


class GpuLauncher(Launcher):
    """`launches`: (function handle, grid or None for a saturating grid, block) in launch order."""

    def __init__(self, device: Device, launches: list[tuple[Any, int | None, int]], kernel_name: str, params: list,
                 nslots: int, returns: list, error_table: list, program, ret_matrix: object = None,
                 scratch_slots: int = 0, tape_threads: int = 0):
        self.device = device
        self.tape_threads = tape_threads  # threads with a region of the deep tape (codegen/nvptx.py)
        self.launches = [(fn, min(grid or (1 << 31), saturating_grid(device, block)), block)
                         for fn, grid, block in launches]
        self.dctx = self.dtape = 0
        super().__init__(kernel_name, params, 0, nslots, returns, error_table, program, ret_matrix, 0, scratch_slots)
        self.dctx = device.alloc(self.buf.nbytes)
        # values to read back, or an error to report at its line; and, until Python-scope access to fields
        # synchronizes by itself, every launch on an asynchronous device (the GPU): the host sees its results
        self.waits = bool(returns) or bool(error_table) or device.asynchronous
        self._ret = self.buf[self.ret_slot:self.ret_slot + len(returns)]
        if device.asynchronous:  # a GPU: host arrays are not its memory
            self.launch = self._device_arrays_only(self.launch)

    def _device_arrays_only(self, launch):
        def checked(*args):
            if any(isinstance(a, np.ndarray) for a in args):
                raise SimgradNotSupportedError(
                    f"kernel {self.kernel_name}: a numpy array argument on arch=cuda (its memory is the host's); "
                    "pass a ti.ndarray (device memory) and copy with from_numpy/to_numpy", caller_loc())
            return launch(*args)

        return checked

    def native_entry(self, address: int):
        return self.run

    def run(self, _addr: int) -> None:
        d = self.device
        d.to_device(self.dctx, self.buf)
        for fn, grid, block in self.launches:
            d.launch(fn, grid, block, self.dctx)
        if self.waits:
            d.synchronize()
            if len(self._ret):
                d.to_host(self._ret, self.dctx + 8 * self.ret_slot)

    def attach_tape(self, entries: int) -> None:
        """The serial part's tape in device memory, and, for a tape too deep for a thread's local memory, a
        region of `entries` per thread of the parallel segments (codegen/nvptx.py caps their grids to
        `tape_threads`)."""
        self.dtape = self.device.alloc(8 * entries * (self.tape_threads + 1))
        self.buf[CTX_TAPE] = self.dtape + 8 * entries
        self.buf[CTX_TAPE_SERIAL] = self.dtape
        self.buf[CTX_TAPE_CAP] = entries

    def __del__(self):
        try:
            for p in (self.dctx, self.dtape):
                if p:
                    self.device.free(p)
        except Exception:  # interpreter shutdown
            pass
