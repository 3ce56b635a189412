"""ti.algorithms: Taichi 1.7.4's `parallel_sort` and `PrefixSumExecutor` on 1-D fields and ndarrays, as
simgrad kernels (_sort.py: a stable radix sort; _scan.py: an inclusive prefix sum; private modules, so
dir(ti.algorithms) shows only the two public names, as Taichi's does)."""

from simgrad.algorithms._scan import PrefixSumExecutor
from simgrad.algorithms._sort import parallel_sort

__all__ = ["parallel_sort", "PrefixSumExecutor"]
