"""A pool of Worker actors on Ray and the map over it: `map_value_and_grad(build, params_list)`.

Scheduling is Ray's (actors, the object store, restarts); the pool only keeps every worker busy with up to
`depth` queued tasks and gives each params its one result. Compile once: the first worker runs the first
task alone; its `cache_bundle()` (the kernel cache files it wrote) is a constructor argument of the others,
so Ray starts them when it exists and they build from the cache instead of compiling again. Fault tolerance
is Ray's: a worker process that dies is restarted (`max_restarts`, build() runs again) and its queued and
running tasks are retried (`max_task_retries`); results are keyed by the task, so none is lost or doubled.
Ctrl-C (or any error) kills the pool's workers before it propagates.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
import ray

from simgrad.distributed.worker import Worker

Params = dict[str, np.ndarray]
Result = tuple[float, dict[str, np.ndarray]]


def ensure_ray() -> None:
    """ray.init() when Ray is not running yet: a local Ray on this machine, or the cluster RAY_ADDRESS names."""
    if not ray.is_initialized():
        ray.init()


class WorkerPool:
    """`num_workers` Worker actors of `cpus_per_worker` CPUs each, all built by `build`; reusable across maps.

    num_workers=None: as many as the cluster's CPUs allow (at most the number of params of the first map).
    cache_dir: the kernel cache directory of the workers (None: simgrad's default, shared on one machine).
    """

    def __init__(self, build: Callable[[], Any], num_workers: int | None = None, *, cpus_per_worker: float = 1,
                 cache_dir: str | None = None, max_restarts: int = 3, max_task_retries: int = 3, depth: int = 2):
        ensure_ray()
        self.build = build
        self.cpus_per_worker = cpus_per_worker
        self.num_workers = num_workers
        self.cache_dir = None if cache_dir is None else str(cache_dir)
        self.depth = max(1, depth)
        self._actor_class = ray.remote(Worker).options(num_cpus=cpus_per_worker, max_restarts=max_restarts,
                                                       max_task_retries=max_task_retries)
        self.actors: list = []

    def _start(self, wanted: int, first: Params | None) -> list:
        """Starts the workers; the first one runs `first` alone, the others build from its cache files."""
        if self.actors:
            return []
        n = self.num_workers or max(1, int(ray.cluster_resources().get("CPU", 1) // self.cpus_per_worker))
        n = max(1, min(n, wanted))
        # build travels by value with each actor (a kernel or field inside it refuses here, at its line); the
        # bundle is fetched here, not passed as a reference: a restarted actor needs its arguments again
        first_actor: Any = self._actor_class.remote(self.build, self.cache_dir)
        self.actors = [first_actor]
        started = []
        if first is not None:
            started.append(first_actor.value_and_grad.remote(first))
        bundle = ray.get(first_actor.cache_bundle.remote()) if n > 1 else None
        self.actors += [self._actor_class.remote(self.build, self.cache_dir, None, bundle) for _ in range(n - 1)]
        return started

    def imap(self, params_list: Sequence[Params], progress: bool = True) -> Iterator[tuple[int, Result]]:
        """(index, (loss, grads)) for every params, in the order they finish."""
        params_list = list(params_list)
        if not params_list:
            return
        bar = _progress_bar(len(params_list)) if progress else None
        pending: dict = {}  # task ref -> (index, actor)
        todo = iter(range(len(params_list)))
        try:
            for ref in self._start(len(params_list), params_list[0]):
                pending[ref] = (next(todo), self.actors[0])
            queued = {id(a): 0 for a in self.actors}
            if pending:
                queued[id(self.actors[0])] = 1

            def submit(actor) -> bool:
                i = next(todo, None)
                if i is None:
                    return False
                pending[actor.value_and_grad.remote(params_list[i])] = (i, actor)
                queued[id(actor)] += 1
                return True

            for _ in range(self.depth):
                for a in self.actors:
                    if queued[id(a)] < self.depth:
                        submit(a)
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    i, actor = pending.pop(ref)
                    queued[id(actor)] -= 1
                    result = ray.get(ref)
                    if bar is not None:
                        bar.update(1)
                    while queued[id(actor)] < self.depth and submit(actor):
                        pass
                    yield i, result
        except BaseException:  # Ctrl-C, a task's error, or the consumer stopped early: stop the sweep
            self.close()
            raise
        finally:
            if bar is not None:
                bar.close()

    def map(self, params_list: Sequence[Params], progress: bool = True) -> list[Result]:
        """[(loss, grads), ...] in the order of params_list."""
        results: list = [None] * len(params_list)
        for i, r in self.imap(params_list, progress=progress):
            results[i] = r
        return results

    def stats(self) -> list[dict[str, int]]:
        """Each worker's compile counts (Worker.stats)."""
        return ray.get([a.stats.remote() for a in self.actors])

    def close(self) -> None:
        for a in self.actors:
            try:
                ray.kill(a, no_restart=True)
            except Exception:
                pass
        self.actors = []

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def imap_value_and_grad(build: Callable[[], Any], params_list: Sequence[Params], num_workers: int | None = None,
                        progress: bool = True, **pool_options) -> Iterator[tuple[int, Result]]:
    """(index, (loss, grads)) as tasks finish, with a tqdm progress bar when tqdm is installed."""
    pool = WorkerPool(build, num_workers, **pool_options)
    try:
        yield from pool.imap(params_list, progress=progress)
    finally:
        pool.close()


def map_value_and_grad(build: Callable[[], Any], params_list: Sequence[Params], num_workers: int | None = None,
                       **options) -> list[Result]:
    """build() is called once in each worker and returns f(params: dict[str, np.ndarray]) -> (loss: float,
    grads: dict[str, np.ndarray]); the result is the list of (loss, grads) in the order of params_list."""
    progress = options.pop("progress", True)
    with WorkerPool(build, num_workers, **options) as pool:
        return pool.map(params_list, progress=progress)


def _progress_bar(total: int):
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc="simgrad.distributed", unit="task")
