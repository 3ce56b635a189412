"""What users touch: kernels, fields, SNodes, matrices, the Tape. `impl` answers the taichi.lang.impl
names public programs use, `ops` taichi.lang.ops (`ti.lang.ops.add(u, v)` in Taichi's own tests): simgrad's
module is lang/operators.py, named apart from ir/ops.py."""

from simgrad.lang import impl  # noqa: F401
from simgrad.lang import operators as ops  # noqa: F401
