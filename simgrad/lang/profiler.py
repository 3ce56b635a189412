"""`ti.profiler`: per-kernel launch counts and times (enable with ti.init(kernel_profiler=True))."""

from simgrad.lang.program import get_program


def print_kernel_profiler_info(mode: str = "count") -> None:
    print(get_program().profiler.report())


def clear_kernel_profiler_info() -> None:
    get_program().profiler.clear()


def get_kernel_profiler_total_time() -> float:
    return sum(sum(v) for v in get_program().profiler.records.values())


class KernelProfilerQueryResult:
    """What `query_kernel_profiler_info(name)` returns, as Taichi's object: launch count and times in ms."""

    __slots__ = ("counter", "min", "max", "avg")

    def __init__(self, counter: int, min: float, max: float, avg: float):  # noqa: A002 (Taichi's names)
        self.counter, self.min, self.max, self.avg = counter, min, max, avg

    def __repr__(self) -> str:
        return (f"KernelProfilerQueryResult(counter={self.counter}, min={self.min}, max={self.max}, "
                f"avg={self.avg})")


def query_kernel_profiler_info(name: str) -> KernelProfilerQueryResult:
    """Launches of kernel `name` (its __name__) since the last clear: counter, and min/max/avg wall time in
    milliseconds, as Taichi reports them; zeros for a kernel never launched."""
    ts = get_program().profiler.records.get(name, [])
    if not ts:
        return KernelProfilerQueryResult(0, 0.0, 0.0, 0.0)
    return KernelProfilerQueryResult(len(ts), 1e3 * min(ts), 1e3 * max(ts), 1e3 * sum(ts) / len(ts))
