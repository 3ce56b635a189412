"""What users touch: kernels, fields, SNodes, matrices, the Tape. `impl` answers the taichi.lang.impl
names public programs use."""

from simgrad.lang import impl  # noqa: F401
