#!/usr/bin/env bash
# The prepared GPU check of issue 22 for one device session (an H100; 15 minutes of device time in all, 10 per
# command). Run from the repository root on the device machine; results go to $OUT.
#
# Preparation, on the development machine (no device time), once per session:
#   echo /.whl/ >> .git/info/exclude
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
#     --platform manylinux2014_x86_64 -d .whl taichi==1.7.4 llvmlite==$(.venv/bin/python -c \
#     'import llvmlite; print(llvmlite.__version__)')
#   # taichi 1.7.4 needs no other wheel the device image lacks (its image has numpy, cuda-bindings, pytest,
#   # pytest-xdist, scipy, pillow); `unzip -p .whl/taichi-*.whl '*/METADATA' | grep ^Requires-Dist` to check.
#   # llvmlite is carried so that the device compiles with the LLVM simgrad is tested with here.
# The device call (one command, leaves time for a rerun):
#   run(command="bash benchmarks/gpu/run_on_device.sh", carry=[".whl"], timeout_s=540)
# Then, if device time is left, the unmodified DiffTaichi programs side by side on the GPU:
#   benchmarks/gpu/originals_on_device.sh (its header says what to carry).
set -u -o pipefail
OUT=${OUT:-/tmp/simgrad-gpu-out}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
PY=python3
log() { echo "== $*" | tee -a "$OUT/summary.txt"; }

if ls .whl/*.whl >/dev/null 2>&1; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    || { log "wheel install failed"; exit 1; }
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD
fi
# simgrad itself from the tree (its package data are files in simgrad/)
nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1
log "$(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>&1)"
log "python $($PY -c 'import sys, llvmlite, numpy; print(sys.version.split()[0], "llvmlite", llvmlite.__version__, "numpy", numpy.__version__)')"
log "cuda available: $($PY -c 'from simgrad.runtime import device; print(device.cuda_available())' 2>&1)"
export PATH=$PATH:/usr/local/cuda/bin
if [ ! -f /usr/local/cuda/nvvm/libdevice/libdevice.10.bc ]; then  # else codegen/nvptx.py finds it
  export SIMGRAD_LIBDEVICE=$(find /usr/local /opt -name libdevice.10.bc 2>/dev/null | head -1)
fi
log "libdevice: ${SIMGRAD_LIBDEVICE:-/usr/local/cuda/nvvm/libdevice/libdevice.10.bc}; ptxas: $(command -v ptxas)"

# 1. simgrad's PTX on the GPU through CudaDriver, against the CPU (correctness + kernel ms)
timeout 120 $PY benchmarks/gpu/ptx_on_device.py 2>&1 | tee "$OUT/ptx_on_device.txt"
log "ptx_on_device rc=${PIPESTATUS[0]}"

# 2. tests/gpu (the CudaDriver test runs here), then the PTX check over a part of the suite
timeout 100 $PY -m pytest -q -x -p no:cacheprovider tests/gpu 2>&1 | tee "$OUT/tests_gpu.txt" | tail -3
log "tests/gpu rc=${PIPESTATUS[0]}"
SIMGRAD_PTX_CHECK=1 timeout 100 $PY -m pytest -q -n 8 -p no:cacheprovider tests/autodiff tests/codegen \
  2>&1 | tee "$OUT/ptx_check.txt" | tail -3
log "ptx check rc=${PIPESTATUS[0]}"

# 3. the real-GPU runtime (runtime/gpu_launch.py over CudaDriver; SIMGRAD_CUDA_RUNTIME=1 enables it until
#    runtime/device.py CUDA_RUNTIME_READY is True): its checks and timings, then a part of the suite on it
SIMGRAD_CUDA_RUNTIME=1 timeout 120 $PY benchmarks/gpu/runtime_on_device.py 2>&1 | tee "$OUT/runtime_on_device.txt"
log "runtime_on_device rc=${PIPESTATUS[0]}"
SIMGRAD_CUDA_RUNTIME=1 TI_ARCH=cuda timeout 150 $PY -m pytest -q -n 4 -p no:cacheprovider tests/gpu tests/autodiff \
  2>&1 | tee "$OUT/cuda_suite.txt" | tail -3
log "arch=cuda suite on the GPU rc=${PIPESTATUS[0]}"

# 4. taichi 1.7.4's CUDA backend on the same GPU, for the side-by-side figures (launch overhead, a saxpy)
timeout 60 $PY - <<'PYEOF' 2>&1 | tee "$OUT/taichi_cuda.txt"
import time
import numpy as np
import taichi as ti
ti.init(arch=ti.cuda)
n = 1 << 20
x = ti.field(ti.f32, n); y = ti.field(ti.f32, n)
@ti.kernel
def saxpy(a: ti.f32):
    for i in x:
        y[i] = a * x[i] + ti.sin(y[i])
@ti.kernel
def tiny():
    y[0] += 1.0
for k in (saxpy, tiny):
    args = (2.0,) if k is saxpy else ()
    k(*args); ti.sync()
    t = time.perf_counter()
    for _ in range(1000):
        k(*args)
    ti.sync()
    print(f"taichi 1.7.4 cuda {k.__name__}: {(time.perf_counter() - t) * 1e3:.4f} us/launch (1000 launches)")
PYEOF
log "done"
