"""`ti.profiler`: per-kernel launch counts and times (enable with ti.init(kernel_profiler=True))."""

from simgrad.lang.program import get_program


def print_kernel_profiler_info(mode: str = "count") -> None:
    print(get_program().profiler.report())


def clear_kernel_profiler_info() -> None:
    get_program().profiler.clear()


def get_kernel_profiler_total_time() -> float:
    return sum(sum(v) for v in get_program().profiler.records.values())


def query_kernel_profiler_info(name: str):
    ts = get_program().profiler.records.get(name, [])
    return {"counter": len(ts), "min": min(ts, default=0.0), "max": max(ts, default=0.0),
            "avg": sum(ts) / len(ts) if ts else 0.0}
