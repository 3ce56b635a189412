#!/usr/bin/env bash
# The second call of a device session (issue 22 item 5): the unmodified DiffTaichi programs with arch=cuda, under
# simgrad (SIMGRAD_CUDA_RUNTIME=1) and taichi 1.7.4 side by side on the same GPU (benchmarks/originals.py: each
# program in a fresh process per framework; losses compared; s/iter). Results go to $OUT.
#
# Preparation on the development machine (as for run_on_device.sh, whose .whl folder it reuses), plus the programs:
#   echo /.difftaichi/ >> .git/info/exclude
#   mkdir -p .difftaichi && cp -r <difftaichi checkout>/examples .difftaichi/   # 0.5 MB: a path, nothing committed
# The device call:
#   run(command="bash benchmarks/gpu/originals_on_device.sh", carry=[".whl", ".difftaichi"], timeout_s=420)
set -u -o pipefail
OUT=${OUT:-/tmp/simgrad-gpu-out}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
PY=python3
if ls .whl/*.whl >/dev/null 2>&1; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    || { echo "wheel install failed"; exit 1; }
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD
fi
export PATH=$PATH:/usr/local/cuda/bin
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader > "$OUT/originals_gpu.txt" 2>&1
export SIMGRAD_CUDA_RUNTIME=1
for prog in mass_spring_simple billiards diffmpm_simple wave mass_spring smoke_taichi_gpu diffmpm; do
  timeout 100 $PY benchmarks/originals.py --difftaichi .difftaichi --arch cuda --iters 3 --timeout 90 \
    --simgrad-python $PY --taichi-python $PY --only "$prog" --json "$OUT/originals_cuda.json" \
    2>&1 | tail -4 | tee -a "$OUT/originals_gpu.txt"
done
$PY benchmarks/originals.py --difftaichi .difftaichi --table-only --json "$OUT/originals_cuda.json" \
  > "$OUT/originals_cuda.md" 2>&1
cat "$OUT/originals_cuda.md"
