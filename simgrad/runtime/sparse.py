"""Memory of sparse SNodes: one pool of fixed-size blocks per pointer / dynamic node (a pointer node's cells; a
dynamic node's chunks, chained into lists), and a zero block and a discard block per sparse node, all described by
a table that compiled kernels read (context slot CTX_SPARSE) and update with atomics.

A pool reserves address space for every block its node could ever need (mmap with MAP_NORESERVE: pages
cost memory only once touched) and hands blocks out by bumping an index (an atomic add: many threads
activate at once without a lock); blocks given back by deactivation are zeroed and kept on a free list,
under the pool's spin lock, that the next activations take from first; once every block of a pool is
free again (deactivate_all) the pool starts over at its first, already resident, block. Kernels
allocate in codegen/sparse.py `@sg_sparse_alloc`; a pool that runs out reports an error through the
kernel's error buffer and hands out the node's discard block, so the kernel's remaining writes land
nowhere harmful. Reads of an inactive
cell are pointed at the node's zero block (they see 0 and activate nothing).

On arch=cuda the memory comes from the device (`Device.alloc_shared` for the table, lists and side blocks,
`Device.reserve` for pool bodies, which need not be zeroed: the GPU's allocator zeroes each fresh block).
"""

from __future__ import annotations

import ctypes
import mmap
from collections.abc import Callable

import numpy as np

MAX_POOLS = 1024
#: the words of one pool's entry in the table (i64 each)
(POOL_LOCK, POOL_NEXT, POOL_CAPACITY, POOL_BASE, POOL_FREE, POOL_BLOCK, POOL_FREECOUNT, POOL_ZERO, POOL_DISCARD,
 POOL_LISTS, POOL_BATCHES, POOL_LOST) = range(12)
#: fresh blocks a thread takes from a pool at a time (one shared atomic add each: activation from many threads
#: went 5.5 -> 1.5 ms for 79k blocks), and the pool threads that can; a pool capped by device_memory_GB can
#: report running out while up to BATCH - 1 blocks per thread are still taken but unused
BATCH = 16
MAX_THREADS = 4096
POOL_WORDS = 16
#: struct-fors one kernel may run over the same first sparse node (each keeps its own list of active cells)
MAX_LISTS = 16
#: address space one pool may reserve; a node that could need more is capped (running out is an error)
MAX_RESERVE = 1 << 38

_libc = ctypes.CDLL(None, use_errno=True)
_libc.mmap.restype = ctypes.c_void_p
_libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_long]
_libc.munmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
_MAP_NORESERVE = getattr(mmap, "MAP_NORESERVE", 0x4000)


def _reserve(nbytes: int) -> int:
    flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | _MAP_NORESERVE
    addr = _libc.mmap(None, nbytes, mmap.PROT_READ | mmap.PROT_WRITE, flags, -1, 0)
    if addr in (None, ctypes.c_void_p(-1).value):
        raise MemoryError(f"could not reserve {nbytes} bytes of address space for a sparse SNode pool")
    return int(addr)


class SparseMemory:
    """The pool table of one program (lang/program.py) and the memory behind it."""

    def __init__(self, reserve_limit: int = MAX_RESERVE,
                 device_alloc: Callable[[int, bool], int] | None = None) -> None:
        self.reserve_limit = reserve_limit  # bytes one pool may reserve (ti.init(device_memory_GB=...))
        self.device_alloc = device_alloc  # (bytes, zeroed) -> address of device memory; None: host mmap
        # the table is mapped with the first pool (a program without sparse nodes maps nothing; a
        # per-program malloc of this size would leave the allocator's heap fragmented over init cycles)
        self.table = np.zeros((0, POOL_WORDS), dtype=np.int64)
        self.address = 0
        self.count = 0
        self.touched: dict[int, int] = {}  # pool -> most blocks ever bumped (across restarts)
        self._maps: list[tuple[int, int]] = []  # (address, bytes) to unmap on release

    def _ensure_table(self) -> None:
        if self.address:
            return
        nbytes = MAX_POOLS * POOL_WORDS * 8
        self.address = self._map(nbytes)
        words = (ctypes.c_int64 * (MAX_POOLS * POOL_WORDS)).from_address(self.address)
        self.table = np.ctypeslib.as_array(words).reshape(MAX_POOLS, POOL_WORDS)

    def add_pool(self, block_size: int, capacity: int, cells: int, line: bool = True) -> int:
        """A pool of `capacity` blocks of `block_size` bytes (capacity 0: a bitmasked node's zero and
        discard blocks only) for a node of `cells` cells in all. Returns its id, the index the kernels use.
        Blocks of 64 bytes or more are rounded up to whole cache lines unless `line` is false (a dynamic
        node's chunks: 8 bytes of link and the cells, as Taichi's, are rounded up to 8 bytes only).
        With it come MAX_LISTS lists of `cells` i32 each: a struct-for whose first sparse node this is
        lists the active cells there before its parallel loop starts (as Taichi's listgen), so cells it
        activates itself (an adjoint's scatter) are not visited by the same loop."""
        self._ensure_table()
        if self.count >= MAX_POOLS:
            raise RuntimeError(f"more than {MAX_POOLS} sparse SNodes in one program")
        pid = self.count
        self.count += 1
        block_size = max(8, (block_size + 63) // 64 * 64 if block_size >= 64 and line else (block_size + 7) // 8 * 8)
        row = self.table[pid]
        row[POOL_BLOCK] = block_size
        if capacity:  # room for the blocks threads hold in unfinished batches (BATCH each)
            capacity = min(capacity + BATCH * MAX_THREADS, self.reserve_limit // block_size)
        row[POOL_CAPACITY] = capacity
        if capacity:
            row[POOL_BASE] = self._map(capacity * block_size, zeroed=False)
        side = self._map(2 * block_size)  # the zero block, then the discard block
        row[POOL_ZERO], row[POOL_DISCARD] = side, side + block_size
        row[POOL_LISTS] = self._map(MAX_LISTS * 4 * max(cells, 1))
        row[POOL_BATCHES] = self._map(MAX_THREADS * 64)  # per thread [next, end], 64 bytes apart
        return pid

    def _map(self, nbytes: int, zeroed: bool = True) -> int:
        nbytes = (nbytes + mmap.PAGESIZE - 1) // mmap.PAGESIZE * mmap.PAGESIZE
        if self.device_alloc is not None:  # freed with the device's memory
            return self.device_alloc(nbytes, zeroed)
        addr = _reserve(nbytes)
        self._maps.append((addr, nbytes))
        return addr

    def block_size(self, pid: int) -> int:
        return int(self.table[pid, POOL_BLOCK])

    def _unused_batches(self, pid: int) -> int:
        """Blocks threads have taken in batches but not handed out yet."""
        words = (ctypes.c_int64 * (MAX_THREADS * 8)).from_address(int(self.table[pid, POOL_BATCHES]))
        batches = np.ctypeslib.as_array(words).reshape(MAX_THREADS, 8)
        return int(np.maximum(batches[:, 1] - batches[:, 0], 0).sum())

    def _clear_batches(self, pid: int) -> None:
        ctypes.memset(int(self.table[pid, POOL_BATCHES]), 0, MAX_THREADS * 64)

    def _handed_out(self, pid: int) -> int:
        """Blocks bumped off the pool and handed to a slot (installed, or freed, or lost to a race)."""
        row = self.table[pid]
        return min(int(row[POOL_NEXT]), int(row[POOL_CAPACITY])) - self._unused_batches(pid)

    def usage_of(self, pid: int) -> dict[str, int]:
        """A pool's blocks in use, blocks ever installed in a slot (bumped, less those still in a thread's
        batch and those that lost a race to install and went to the free list), and the bytes those hold."""
        row = self.table[pid]
        bumped = self._handed_out(pid)
        self.touched[pid] = max(self.touched.get(pid, 0), bumped - int(row[POOL_LOST]))
        return {"live_blocks": bumped - int(row[POOL_FREECOUNT]), "touched_blocks": self.touched[pid],
                "block_bytes": int(row[POOL_BLOCK]), "touched_bytes": self.touched[pid] * int(row[POOL_BLOCK])}

    def restart_if_empty(self, pid: int) -> None:
        """After a deactivate_all: when no block of the pool is in use, forget the free list and bump from
        the first block again (every freed block was zeroed), so activations take the lock-free path."""
        row = self.table[pid]
        used = self._handed_out(pid)
        if row[POOL_CAPACITY] and used == row[POOL_FREECOUNT]:
            self.touched[pid] = max(self.touched.get(pid, 0), used - int(row[POOL_LOST]))
            row[POOL_NEXT] = row[POOL_FREE] = row[POOL_FREECOUNT] = row[POOL_LOST] = 0
            self._clear_batches(pid)

    def release(self) -> None:
        self.table = np.zeros((0, POOL_WORDS), dtype=np.int64)
        for addr, nbytes in self._maps:
            _libc.munmap(ctypes.c_void_p(addr), nbytes)
        self._maps.clear()
        self.count = 0
        self.address = 0
