#!/usr/bin/env bash
# benchmarks/gpu_check.py on a GPU machine that has PyTorch with CUDA but not the rest: the
# wheels in .whl/ (gsplat, pycolmap, plyfile, PyMaxflow, kornia, kornia_rs for the machine's
# Python; 53 MB, more than 64 MiB with the statue's scene folder; without kornia the test
# views' SSIM cannot be computed) go into /tmp/site beside its PyTorch, and the
# check runs from the repository. Arguments are those of `python -m benchmarks.gpu_check run`;
# the exit code is its (3: the training stopped at --deadline; run the same command again to
# continue).
#
#   bash benchmarks/gpu_check.sh --scene gpu_scenes/statue --deadline 480 --out $OUT/gpu_check.json
#
# --out is written after every stage from the training on: a command stopped by a time limit
# leaves in it what it measured.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -d /tmp/site/gsplat ]; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
fi
export PYTHONPATH="/tmp/site:$PWD" PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
python3 -c "import torch, gsplat; print('torch', torch.__version__, 'gsplat', gsplat.__version__, torch.cuda.get_device_name(0))"
exec python3 -m benchmarks.gpu_check run "$@"
