"""The kernel context ABI: what each 8-byte slot of the buffer passed to `entry(ptr ctx)` holds.

Generated code (codegen/) reads these slots and the launcher (runtime/launch.py) and the program
(lang/program.py) fill them, so the numbers live here, in one place both sides import.
"""

from __future__ import annotations

CTX_ROOTS = 0  # the roots table: one base address per SNode tree
CTX_ERR = 1  # the error buffer: [code, value, args...] of the first error a kernel reports
CTX_RNG = 2  # per-thread random states (16 bytes each)
CTX_PFOR = 3  # the thread pool's parallel_for(task, closure, begin, end, grain)
CTX_TAPE = 4  # the autodiff tape of the parallel tasks (one region per pool thread)
CTX_TAPE_CAP = 5  # tape capacity per thread, in entries
CTX_TAPE_SERIAL = 6  # the tape of the serial part of the kernel
CTX_NTHREADS = 7  # number of pool threads
CTX_CANCEL = 8  # the process's cancel flag (i32, set by Ctrl-C; runtime/threadpool.py)
CTX_SPARSE = 9  # the sparse SNode pool table (runtime/sparse.py)
CTX_ARGS = 10  # first argument slot; return values follow the arguments

# The error buffer: code, value, then up to ERR_MAX_ARGS values of a failed assert's message (64-bit words)
ERR_ARGS = 2
ERR_MAX_ARGS = 32
ERR_WORDS = ERR_ARGS + ERR_MAX_ARGS

# The error code a kernel reports when the cancel flag stopped it (the launcher raises KeyboardInterrupt).
ERR_INTERRUPTED = -1

# Slots the program fills identically for every kernel (Program.context_header), in slot order.
HEADER_SLOTS = (CTX_ROOTS, CTX_ERR, CTX_RNG, CTX_PFOR, CTX_CANCEL, CTX_SPARSE)
