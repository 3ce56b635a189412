"""The one LLVM JIT of the process: target machine, -O3 pipeline, native code, on-disk object cache.

Everything native (kernels, the thread pool) goes through here so that there is one target
description and one cache policy.
"""

from __future__ import annotations

import hashlib
import os
import threading
from pathlib import Path

import llvmlite
import llvmlite.binding as llvm

from simgrad.debug import debug_level
from simgrad.runtime.isel_guard import merge_same_address_loads

#: a line in a module's text that turns LLVM's SLP vectoriser off for it (codegen/cpu.py says when); being in
#: the text, it is in the object cache's key
NO_SLP = "; simgrad: no-slp"

_COMPILER_VERSION = "simgrad-jit-1"


def tuned_features(cpu: str, features: str) -> str:
    """The host's features plus the tuning LLVM's model of the CPU lacks. AMD Zen's AVX-512 scatters are slow
    and a gather after them waits for them: a loop over an interleaved grid (diffmpm3d's grid_op: 56-byte cells,
    3 components stored) vectorised with scatters took 4.0 ms on Zen 5, 0.67 ms with its stores scalarised
    (`prefer-no-scatter`, an LLVM x86 tuning feature: the cost model then weighs scalar stores instead)."""
    if cpu.startswith("znver") and "+prefer-no-scatter" not in features.split(","):
        return features + ",+prefer-no-scatter" if features else "+prefer-no-scatter"
    return features


def default_cache_dir() -> Path:
    base = os.environ.get("SIMGRAD_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "simgrad"
    )
    return Path(base)


class Jit:
    """Compiles LLVM IR text to native code inside this process (MCJIT) and caches objects on disk."""

    def __init__(self) -> None:
        llvm.initialize_native_target()
        llvm.initialize_native_asmprinter()
        self.triple = llvm.get_process_triple()
        self.cpu = llvm.get_host_cpu_name()
        self.features = tuned_features(self.cpu, llvm.get_host_cpu_features().flatten())
        self.target_machine = self.new_target_machine()  # for optimising and emitting objects
        self.data_layout = str(self.target_machine.target_data)
        self.cache_enabled = True
        self.cache_dir = default_cache_dir()
        self.stats = {"compiled": 0, "cache_hits": 0, "kernel_hits": 0}
        self.code = CodeSpace(self)  # native code for the life of the process (the thread pool)

    # -- compilation -------------------------------------------------------------------------
    def _optimize(self, module: llvm.ModuleRef, slp: bool = True) -> None:
        pto = llvm.create_pipeline_tuning_options(speed_level=3)
        pto.loop_vectorization = True
        pto.slp_vectorization = slp
        pto.loop_unrolling = True
        builder = llvm.create_pass_builder(self.target_machine, pto)
        builder.getModulePassManager().run(module, builder)

    def vector_bits(self) -> int:
        """The width of the host's widest vector registers (what passes/lanes.py sizes its lanes by)."""
        features = self.features.split(",")
        return 512 if "+avx512f" in features else 256 if "+avx" in features else 128

    def target_id(self) -> tuple:
        """What native code depends on besides its LLVM IR."""
        return (_COMPILER_VERSION, llvmlite.__version__, self.triple, self.cpu, self.features)

    def _cache_key(self, ir_text: str) -> str:
        h = hashlib.sha256()
        for part in (*self.target_id(), ir_text):
            h.update(part.encode())
            h.update(b"\0")
        return h.hexdigest()[:40]

    def object_for(self, ir_text: str, cache_key: str | None = None) -> bytes:
        """Native object code for `ir_text`, from the disk cache when present. SIMGRAD_DEBUG >= 3 prints
        the optimised LLVM IR (4: and the assembly) either way: a cache hit optimises it just to print it."""
        key = cache_key or self._cache_key(ir_text)
        path = self.cache_dir / f"{key}.o"
        level = debug_level()
        if self.cache_enabled and path.exists():
            self.stats["cache_hits"] += 1
            if level >= 3:
                self._optimized(ir_text, level)
            return path.read_bytes()
        context = llvm.create_context()  # constants and types LLVM interns die with it, not with the process
        module = self._optimized(ir_text, level, context)
        guarded = merge_same_address_loads(str(module)) if self.triple.startswith("x86_64") else None
        if guarded is not None:
            module.close()
            module = llvm.parse_assembly(guarded, context=context)
            module.verify()
        obj = self.target_machine.emit_object(module)
        module.close()
        del module, context
        self.stats["compiled"] += 1
        if self.cache_enabled:
            self._write(path, obj)
        return obj

    def _optimized(self, ir_text: str, level: int, context=None) -> llvm.ModuleRef:
        """Parse, verify and optimise; print what the debug level asks for."""
        module = llvm.parse_assembly(ir_text, context=context)
        module.triple = self.triple
        module.data_layout = self.data_layout
        module.verify()
        self._optimize(module, slp=NO_SLP not in ir_text)
        if level >= 3:
            print(str(module))
        if level >= 4:
            print(self.target_machine.emit_assembly(module))
        return module

    def _write(self, path: Path, data: bytes) -> None:
        try:
            self.cache_dir.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.{threading.get_ident()}.tmp")
            tmp.write_bytes(data)
            os.replace(tmp, path)  # readers see the whole file or none
        except OSError:
            pass  # a read-only or full disk only costs us the cache

    # -- kernel entries: an object with what its launcher needs, stored under a frontend-level key --------
    def read_entry(self, key: str) -> bytes | None:
        if not self.cache_enabled:
            return None
        try:
            data = (self.cache_dir / f"{key}.kernel").read_bytes()
        except OSError:
            return None
        self.stats["cache_hits"] += 1
        self.stats["kernel_hits"] += 1
        return data

    def write_entry(self, key: str, data: bytes) -> None:
        if self.cache_enabled:
            self._write(self.cache_dir / f"{key}.kernel", data)

    def load(self, ir_text: str, symbols: list[str], cache_key: str | None = None) -> dict[str, int]:
        """Compile (or fetch) `ir_text`, link it into the process and return symbol addresses."""
        return self.link(self.object_for(ir_text, cache_key), symbols)

    def link(self, obj: bytes, symbols: list[str]) -> dict[str, int]:
        """Add native object code for the life of the process and return the addresses of `symbols`."""
        return self.code.link(obj, symbols)

    def new_target_machine(self) -> llvm.TargetMachine:
        """A target machine for one more execution engine (an engine takes ownership of its machine)."""
        return llvm.Target.from_triple(self.triple).create_target_machine(
            cpu=self.cpu, features=self.features, opt=3, reloc="default", codemodel="jitdefault", jit=True
        )


class CodeSpace:
    """An MCJIT execution engine and the native code linked into it. MCJIT cannot unload one object, but
    closing the engine frees all of them: each ti.init program links its kernels into a CodeSpace of its
    own, closed by ti.reset / the next ti.init (~90 KB of code and LLVM state per kernel otherwise stay
    for the life of the process)."""

    def __init__(self, jit: Jit) -> None:
        from simgrad.runtime import half

        anchor = llvm.parse_assembly("")  # an empty module anchors the engine; objects are added to it
        anchor.triple = jit.triple
        self.engine: llvm.ExecutionEngine | None = llvm.create_mcjit_compiler(anchor, jit.new_target_machine())
        self.lock = threading.Lock()
        if half.needed(jit.triple, jit.features):  # x86 without F16C: f16 code of this space calls these
            self.link(jit.object_for(half.IR), half.SYMBOLS)

    def link(self, obj: bytes, symbols: list[str]) -> dict[str, int]:
        """Add native object code and return the addresses of `symbols`."""
        with self.lock:
            if self.engine is None:
                raise RuntimeError("this program's native code was released (ti.reset / ti.init)")
            self.engine.add_object_file(llvm.ObjectFileRef.from_data(obj))
            self.engine.finalize_object()
            addrs = {name: self.engine.get_function_address(name) for name in symbols}
        missing = [n for n, a in addrs.items() if not a]
        if missing:
            raise RuntimeError(f"native symbols not found after linking: {missing}")
        return addrs

    def global_address(self, name: str) -> int:
        with self.lock:
            assert self.engine is not None
            return self.engine.get_global_value_address(name)

    def close(self) -> None:
        """Free every object linked here. Nothing may call into this code afterwards."""
        with self.lock:
            if self.engine is not None:
                self.engine.close()
                self.engine = None


_jit: Jit | None = None


def get_jit() -> Jit:
    global _jit
    if _jit is None:
        _jit = Jit()
    return _jit
