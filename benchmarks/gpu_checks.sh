#!/bin/bash
# Every GPU check of the project in one run, on a machine with a CUDA GPU (about 5 minutes on
# an H100/H200). From the repository root:
#
#     bash benchmarks/gpu_checks.sh
#
# Needs a python3 with torch (CUDA), numpy, scipy and scikit-image (set PYTHON to choose one).
# Logs go to $OUT, or out/gpu when OUT is not set.
set -o pipefail
OUT=${OUT:-out/gpu}
mkdir -p "$OUT"
PY=${PYTHON:-python3}
"$PY" -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available(), torch.cuda.get_device_name(0) if torch.cuda.is_available() else '')" | tee "$OUT/device.log"
# the CUDA tests (skipped on CPU machines) and the torch/numpy agreement tests
"$PY" -m pytest -q -rs -p no:cacheprovider tests/engine/test_meshing_torch.py \
    tests/engine/test_field.py tests/engine/test_selector.py 2>&1 | tee "$OUT/tests.log"
# the mesher on the GPU: seconds per stage and peak memory at 128, 256, 512
"$PY" benchmarks/bench_meshing.py --res 128 256 512 --device cuda 2>&1 | tee "$OUT/bench_meshing.log"
# the whole reconstruction of the 50k owl (target: at most 5 s at 256 on an H100), and the
# selector's share of the field's time
for mode in fixed learned; do
    "$PY" benchmarks/bench_reconstruct.py --resolutions 128 256 --device cuda \
        --radius-mode "$mode" 2>&1 | tee "$OUT/bench_reconstruct_$mode.log"
done
