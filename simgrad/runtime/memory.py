"""Field memory: one zeroed, 64-byte aligned buffer per SNode tree, and the table of tree roots that
compiled kernels read their base addresses from (so compiled code holds no absolute addresses and can
be cached on disk).

Trees are placed one after another in anonymous mappings (chunks), as Taichi places fields in its root
buffer, never in Python's heap: a write a few elements past a field, which Taichi programs get away with
(differential_evolution.py writes best_fit[max_iter]), lands in the next tree or in the chunk's spare
zero pages instead of malloc's bookkeeping, where it crashed the process later (SIGSEGV while Python
collected garbage). A chunk is unmapped when the program's memory is released."""

from __future__ import annotations

import mmap
from collections.abc import Callable

import numpy as np

MAX_TREES = 4096
CHUNK = 16 << 20  # bytes of address space per mapping (pages cost memory only once touched)
SLACK = 4096  # spare bytes always left after a chunk's last tree
HUGE_PAGE = 2 << 20


def _mapping(n: int) -> mmap.mmap:
    """n bytes of anonymous memory, backed by transparent huge pages where the kernel gives them on request
    (THP in "madvise" mode): numpy asks for them for its large arrays, and without them a 10M-element saxpy ran
    at half the bandwidth (TLB misses) once fields moved out of numpy's allocations."""
    m = mmap.mmap(-1, n, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)  # shared anonymous memory is shmem: no THP
    if n >= HUGE_PAGE and hasattr(mmap, "MADV_HUGEPAGE"):
        try:
            m.madvise(mmap.MADV_HUGEPAGE)
        except OSError:  # THP off in this kernel: ordinary pages
            pass
    return m


def _host_chunk(n: int) -> np.ndarray:
    return np.frombuffer(_mapping(n), dtype=np.uint8)  # zeroed, page aligned


class Memory:
    """`chunk(n)`: n zeroed bytes as a uint8 array; anonymous host mappings by default, a device's shared
    memory on arch=cuda (runtime/device.py alloc_shared), where the roots table lives too."""

    def __init__(self, chunk: Callable[[int], np.ndarray] = _host_chunk) -> None:
        self._new_chunk = chunk
        if chunk is _host_chunk:
            self.roots = np.zeros(MAX_TREES, dtype=np.uint64)
        else:
            self.roots = chunk(8 * MAX_TREES).view(np.uint64)
        self.roots_address = self.roots.ctypes.data
        self._buffers: dict[int, np.ndarray] = {}
        self._chunk: np.ndarray | None = None
        self._used = 0

    def allocate(self, nbytes: int) -> np.ndarray:
        size = -(-nbytes // 64) * 64
        if self._chunk is None or self._used + size + SLACK > len(self._chunk):
            n = max(CHUNK, -(-(size + SLACK) // mmap.PAGESIZE) * mmap.PAGESIZE)
            self._chunk = self._new_chunk(n)
            self._used = 0
        buf = self._chunk[self._used : self._used + nbytes]
        self._used += size
        return buf

    def set_root(self, tree_id: int, buffer: np.ndarray) -> None:
        if tree_id >= MAX_TREES:
            raise RuntimeError(f"more than {MAX_TREES} SNode trees in one program")
        self._buffers[tree_id] = buffer
        self.roots[tree_id] = buffer.ctypes.data
