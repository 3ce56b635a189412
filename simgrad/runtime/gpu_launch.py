"""The launcher of a kernel on a device (arch=cuda: the GPU through cuda-python, or the simulated GPU).

The arguments are packed into the host context exactly as on the CPU (runtime/launch.py); a launch then uploads
the context to the device (stream-ordered, `Device.upload`), queues the kernel's segments in order
(codegen/nvptx.py `Launch`: grid, block) and returns without waiting, as Taichi's launches do: Python-scope
access of fields and ndarrays synchronizes first (lang/program.py `sync_for_host`), as do ti.sync() and the
next launch that waits. A launch waits only when the kernel returns values, can report an error (its error
table is not empty) or prints, as Taichi's do, or when host arrays were staged for it (`Staging`: numpy arrays
and host tensors on an asynchronous device are copied in before the launch and back after it, as Taichi does
for external arrays on CUDA). A fault of a kernel that did not wait surfaces at the next synchronize (a
DeviceError there)."""

from __future__ import annotations

from typing import Any

import numpy as np

from simgrad.runtime.abi import CTX_TAPE, CTX_TAPE_CAP, CTX_TAPE_SERIAL
from simgrad.runtime.args import LaunchCode
from simgrad.runtime.device import Device, saturating_grid
from simgrad.runtime.launch import Launcher


class Staging:
    """Host arrays passed to one launcher's kernel on an asynchronous device: each copied to device memory when
    its argument is packed (`stage`, one copy per array however often it is passed), and, after the launch,
    back into the host array once the device is done (`finish`), the device copies freed."""

    def __init__(self, device: Device) -> None:
        self.device = device
        self.items: list[tuple[np.ndarray, int]] = []

    def begin(self) -> None:
        """Drop what a launch that failed before its call left (never copied back: its kernel did not run)."""
        if self.items:
            items, self.items = self.items, []
            for _, p in items:
                self.device.free(p)

    def stage(self, a: np.ndarray) -> int:
        for host, p in self.items:
            if host is a:
                return p
        p = self.device.alloc(a.nbytes)
        self.items.append((a, p))
        self.device.upload(p, a)
        return p

    def finish(self) -> None:
        if not self.items:
            return
        items, self.items = self.items, []
        try:
            self.device.synchronize()
            for host, p in items:
                if host.flags.writeable:
                    self.device.to_host(host, p)
        finally:
            for _, p in items:
                self.device.free(p)


class GpuLauncher(Launcher):
    """`launches`: (function handle, grid or None for a saturating grid, block) in launch order. The generated
    launch function (runtime/launch.py) makes the device calls itself: the upload, one prepared call per segment
    (`Device.prepare_launch`: the configuration checked and the kernel parameters built once), and the wait and
    read-back when there is one; no loop or per-launch Python beyond those calls."""

    def __init__(self, device: Device, launches: list[tuple[Any, int | None, int]], kernel_name: str, params: list,
                 nslots: int, returns: list, error_table: list, program, ret_matrix: object = None,
                 scratch_slots: int = 0, prints: bool = False, tape_threads: int = 0):
        self.device = device
        self.tape_threads = tape_threads  # threads with a region of the deep tape (codegen/nvptx.py)
        self.launches = [(fn, min(grid or (1 << 31), saturating_grid(device, block)), block)
                         for fn, grid, block in launches]
        self.dctx = self.dtape = 0
        self.staging = Staging(device)
        # values to read back, an error to report at its line, or printed output (Taichi waits for a kernel
        # with print statements): wait for the device; else return at once
        self.waits = bool(returns) or bool(error_table) or prints
        # a launch on the GPU that did not wait has nothing to report yet (and the host does not touch the error
        # buffer's managed memory while the kernel may run); the synchronous simulated GPU's can be interrupted
        self.reads_errors = self.waits or not device.asynchronous
        self.nreturns = len(returns)
        super().__init__(kernel_name, params, 0, nslots, returns, error_table, program, ret_matrix, 0, scratch_slots)
        self.pack = None  # no native Sequence replays it (lang/graph.py and the Tape launch from Python on a GPU)

    def launch_code(self, env: dict) -> LaunchCode:
        """On an asynchronous device host arrays are staged (`Staging`) and Python after the call synchronizes."""
        if not self.device.asynchronous:
            return super().launch_code(env)
        env["_sync"] = self.device.synchronize
        return LaunchCode(self.kernel_name, env, self.views, on_device=True, staging=self.staging)

    def call_lines(self, env: dict) -> list[str]:
        d = self.device
        self.dctx = d.alloc(self.buf.nbytes)
        env["_upload"] = d.prepare_upload(self.dctx, self.buf)
        lines = ["_upload()"]
        for k, (fn, grid, block) in enumerate(self.launches):
            env[f"_segment{k}"] = d.prepare_launch(fn, grid, block, self.dctx)
            lines.append(f"_segment{k}()")
        if self.waits:
            env["_wait"] = d.synchronize
            lines.append("_wait()")
            ret = self.buf[self.ret_slot:self.ret_slot + self.nreturns]
            if len(ret):
                env["_returns"], env["_to_host"] = ret, d.to_host
                lines.append(f"_to_host(_returns, {self.dctx + 8 * self.ret_slot})")
        return lines

    def native_entry(self, address: int):
        return None  # the generated launch calls the device (call_lines)

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
