"""Field memory: one zeroed, 64-byte aligned buffer per SNode tree, and the table of tree roots that
compiled kernels read their base addresses from (so compiled code holds no absolute addresses and can
be cached on disk)."""

from __future__ import annotations

import ctypes

import numpy as np

MAX_TREES = 4096


class Memory:
    def __init__(self) -> None:
        self.roots = (ctypes.c_void_p * MAX_TREES)()
        self.roots_address = ctypes.addressof(self.roots)
        self._buffers: dict[int, np.ndarray] = {}

    @staticmethod
    def allocate(nbytes: int) -> np.ndarray:
        raw = np.zeros(nbytes + 64, dtype=np.uint8)
        start = (-raw.ctypes.data) % 64
        return raw[start : start + nbytes]

    def set_root(self, tree_id: int, buffer: np.ndarray) -> None:
        if tree_id >= MAX_TREES:
            raise RuntimeError(f"more than {MAX_TREES} SNode trees in one program")
        self._buffers[tree_id] = buffer
        self.roots[tree_id] = buffer.ctypes.data
