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

    def __init__(self, chunk: Callable[[int], np.ndarray] = _host_chunk,
                 free: Callable[[np.ndarray], None] | None = None) -> None:
        self._new_chunk = chunk
        self._free = free  # gives a chunk back (a device's memory); host chunks are unmapped when unreferenced
        self._chunks: dict[int, list] = {}  # address -> [chunk, trees living in it]
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
            left = self._chunk
            if left is not None and self._chunks[left.ctypes.data][1] == 0:  # every tree in it was destroyed
                self._retire(left)
            self._chunk = self._new_chunk(n)
            self._chunks[self._chunk.ctypes.data] = [self._chunk, 0]
            self._used = 0
        self._chunks[self._chunk.ctypes.data][1] += 1
        buf = self._chunk[self._used : self._used + nbytes]
        self._used += size
        return buf

    def set_root(self, tree_id: int, buffer: np.ndarray) -> None:
        if tree_id >= MAX_TREES:
            raise RuntimeError(f"more than {MAX_TREES} SNode trees in one program")
        self._buffers[tree_id] = buffer
        self.roots[tree_id] = buffer.ctypes.data

    def _retire(self, chunk: np.ndarray) -> bool:
        """Forget a chunk no live tree uses; a device's is freed now (True), a host mapping is unmapped once
        nothing refers to it (False: release still returns the tree's pages)."""
        del self._chunks[chunk.ctypes.data]
        if self._free is None:
            return False
        self._free(chunk)
        return True

    def release(self, tree_id: int) -> None:
        """A destroyed tree (SNodeTree.destroy): its root is cleared and its memory given back. A chunk no live
        tree uses any more (and that is not the one being filled) is freed whole (unmapped; a device's chunk
        freed on the device); otherwise the pages wholly inside the tree's buffer go back to the system
        (host mappings: MADV_DONTNEED, they would read zero if touched; nothing reaches them, the tree's
        fields refuse every use). Address ranges inside a live chunk are not reused: the allocator bumps."""
        buf = self._buffers.pop(tree_id, None)
        self.roots[tree_id] = 0
        if buf is None:
            return
        addr = buf.ctypes.data
        for base, entry in list(self._chunks.items()):
            if base <= addr < base + len(entry[0]):
                entry[1] -= 1
                if entry[1] == 0 and entry[0] is not self._chunk and self._retire(entry[0]):
                    return
                break
        owner = buf.base
        while owner is not None and not isinstance(owner, mmap.mmap):
            owner = owner.base if isinstance(owner, np.ndarray) else getattr(owner, "obj", None)  # memoryview
        if owner is None or not hasattr(mmap, "MADV_DONTNEED"):
            return  # a device's chunk still in use: kept until the program is released
        start = addr - np.frombuffer(owner, dtype=np.uint8).ctypes.data
        lo = -(-start // mmap.PAGESIZE) * mmap.PAGESIZE
        hi = (start + buf.nbytes) // mmap.PAGESIZE * mmap.PAGESIZE
        if hi > lo:
            owner.madvise(mmap.MADV_DONTNEED, lo, hi - lo)
