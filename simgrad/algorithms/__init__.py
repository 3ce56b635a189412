"""ti.algorithms: Taichi 1.7.4's `parallel_sort` and `PrefixSumExecutor` on 1-D fields and ndarrays, as
simgrad kernels (sort.py: a stable radix sort; scan.py: an inclusive prefix sum)."""

from simgrad.algorithms.scan import PrefixSumExecutor
from simgrad.algorithms.sort import parallel_sort

__all__ = ["parallel_sort", "PrefixSumExecutor"]
