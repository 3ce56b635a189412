"""The worker: a simgrad program built by the user's function inside its own process, serving
`value_and_grad(params)` and `run(params)` on numpy arrays.

It sizes its thread pool to the CPUs Ray assigned it (`num_cpus`), never to the machine: N workers on one
machine would otherwise run N pools as large as the machine. Kernels it compiles go to simgrad's disk kernel
cache (a shared directory on one machine); `cache_bundle()` hands the files it wrote to the pool, which
installs them in the other workers before they build (compile once, also across machines). The class is
plain Python; WorkerPool makes a Ray actor of it, and a test can use it in-process.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

_CACHE_SUFFIXES = (".kernel", ".o")


@dataclass
class Served:
    """What build() may return when the worker should serve `run` too (a bare function is value_and_grad)."""

    value_and_grad: Callable[[dict[str, np.ndarray]], tuple[float, dict[str, np.ndarray]]]
    run: Callable[[dict[str, np.ndarray]], Any] | None = None


def from_fields(inputs: Mapping[str, Any], loss: Any, forward: Callable[[], None],
                outputs: Mapping[str, Any] | None = None) -> Served:
    """The usual program: params fill the `inputs` fields (name -> field with a gradient), `forward()` computes
    the 0-d `loss` field; value_and_grad differentiates it with ti.ad.Tape, run returns the `outputs` fields."""
    import simgrad as ti

    def load(params: Mapping[str, np.ndarray]) -> None:
        unknown = sorted(set(params) - set(inputs))
        if unknown:
            raise KeyError(f"params {unknown} name no input field (inputs: {sorted(inputs)})")
        for name, value in params.items():
            inputs[name].from_numpy(np.asarray(value))

    def value_and_grad(params):
        load(params)
        with ti.ad.Tape(loss=loss):
            forward()
        return float(loss[None]), {name: field.grad.to_numpy() for name, field in inputs.items()}

    def run(params):
        load(params)
        forward()
        out = {name: field.to_numpy() for name, field in (outputs or {}).items()}
        out["loss"] = float(loss[None])
        return out

    return Served(value_and_grad, run)


def assigned_cpus() -> int:
    """The CPUs Ray gave this process (at least 1; 1 outside a Ray worker)."""
    try:
        import ray

        if ray.is_initialized():
            cpus = ray.get_runtime_context().get_assigned_resources().get("CPU")
            if cpus:
                return max(1, int(cpus))
    except Exception:  # not in a Ray worker: the caller decides
        pass
    return 1


class Worker:
    """build() called once, in this process, with simgrad's thread pool sized to `threads`."""

    def __init__(self, build: Callable[[], Any], cache_dir: str | None = None, threads: int | None = None,
                 bundle: dict[str, bytes] | None = None) -> None:
        self.threads = threads or assigned_cpus()
        # ti.init without cpu_max_num_threads (a build() that calls ti.init itself) reads these
        os.environ["SIMGRAD_NUM_THREADS"] = str(self.threads)
        if cache_dir:
            os.environ["SIMGRAD_CACHE_DIR"] = str(cache_dir)
        import simgrad as ti
        from simgrad.runtime.jit import get_jit

        kw = {"offline_cache_file_path": str(cache_dir)} if cache_dir else {}
        ti.init(arch=ti.cpu, cpu_max_num_threads=self.threads, **kw)
        self._jit = get_jit()
        self.cache_dir = Path(self._jit.cache_dir)
        self.installed = install_cache(self.cache_dir, bundle) if bundle else 0
        self._before = _cache_files(self.cache_dir)
        built = build()
        if isinstance(built, Served):
            self._value_and_grad, self._run = built.value_and_grad, built.run
        elif callable(built):
            self._value_and_grad, self._run = built, None
        else:
            raise TypeError(f"build() returned {type(built).__name__}: it must return the function "
                            "f(params) -> (loss, grads), or a simgrad.distributed.Served")

    def value_and_grad(self, params: dict[str, np.ndarray]) -> tuple[float, dict[str, np.ndarray]]:
        loss, grads = self._value_and_grad(params)
        return float(loss), {name: np.array(g, copy=True) for name, g in grads.items()}

    def run(self, params: dict[str, np.ndarray]) -> Any:
        if self._run is None:
            raise TypeError("this worker's build() returned only value_and_grad: return "
                            "simgrad.distributed.Served(value_and_grad, run) to serve run(params)")
        return _to_numpy(self._run(params))

    def cache_bundle(self) -> dict[str, bytes]:
        """The kernel cache files this worker wrote since it started (what it compiled)."""
        now = _cache_files(self.cache_dir)
        out = {}
        for name, stamp in now.items():
            if self._before.get(name) != stamp:
                try:
                    out[name] = (self.cache_dir / name).read_bytes()
                except OSError:
                    pass
        return out

    def stats(self) -> dict[str, int]:
        """Compile counts of this process: LLVM compiles, kernel cache hits, kernel instantiations, installed
        cache files, threads, and the pid (a restarted worker has a new one)."""
        from simgrad.lang.impl import get_runtime

        return {"compiled": self._jit.stats["compiled"], "kernel_hits": self._jit.stats["kernel_hits"],
                "instantiations": get_runtime().get_num_compiled_functions(), "installed": self.installed,
                "threads": self.threads, "pid": os.getpid()}


def _to_numpy(value):
    if isinstance(value, dict):
        return {k: _to_numpy(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return type(value)(_to_numpy(v) for v in value)
    if hasattr(value, "to_numpy"):  # a field or ndarray: its values, never the object
        return value.to_numpy()
    return value


def _cache_files(cache_dir: Path) -> dict[str, tuple[int, int]]:
    try:
        entries = list(os.scandir(cache_dir))
    except OSError:
        return {}
    out = {}
    for e in entries:
        if e.name.endswith(_CACHE_SUFFIXES):
            st = e.stat()
            out[e.name] = (st.st_mtime_ns, st.st_size)
    return out


def install_cache(cache_dir: Path, bundle: dict[str, bytes]) -> int:
    """Writes the bundle's files that this cache lacks (whole files only: a temporary name, then rename).
    Returns how many it wrote (0 when the directory is the one they came from)."""
    written = 0
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
    except OSError:
        return 0
    for name, data in bundle.items():
        if os.sep in name or not name.endswith(_CACHE_SUFFIXES):
            continue
        path = cache_dir / name
        if path.exists():
            continue
        tmp = path.with_suffix(f".{os.getpid()}.install")
        try:
            tmp.write_bytes(data)
            os.replace(tmp, path)
            written += 1
        except OSError:
            pass
    return written
