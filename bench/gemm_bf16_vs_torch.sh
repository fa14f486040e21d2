#!/bin/sh
# PyTorch's bfloat16 matmul at 1024 (the peer: ../shared/peers/torch_matmul_bf16.py) and
# bin/bench_gemm --quick (float32 and bf16 at 1024) in one invocation, thread count by thread count,
# then the ratio of terrainnet's bf16 to PyTorch's. Without an importable torch it says so and
# prints terrainnet's lines alone.
# Usage: [PEER_RUNS=R] sh bench/gemm_bf16_vs_torch.sh [THREADS ...]   (default: 1 2, R = 3;
#        needs make bin/bench_gemm)
set -u
cd "$(dirname "$0")/.." || exit 1
peer=../shared/peers/torch_matmul_bf16.py
py=
for p in python3 /usr/bin/python3; do
    if command -v "$p" >/dev/null 2>&1 && "$p" -c 'import torch' >/dev/null 2>&1; then py=$p; break; fi
done
[ -x bin/bench_gemm ] || { echo "gemm_bf16_vs_torch: build bin/bench_gemm first (make bin/bench_gemm)"; exit 2; }
[ $# -gt 0 ] || set -- 1 2
out=$(mktemp)
for t in "$@"; do
    if [ -n "$py" ] && [ -f "$peer" ]; then
        "$py" -c 'import torch; print("# torch", torch.__version__, "mkldnn_bf16:", torch.ops.mkldnn._is_mkldnn_bf16_supported() if hasattr(torch.ops.mkldnn, "_is_mkldnn_bf16_supported") else "?")' 2>/dev/null
        "$py" "$peer" --threads "$t" --size 1024 --runs "${PEER_RUNS:-3}" | tee -a "$out"
    else
        echo "# torch not importable (or $peer missing): no peer figure"
    fi
    bin/bench_gemm --threads "$t" --quick | tee -a "$out"
done
awk -F': ' '/^torch_matmul_bf16_1024_t/ { split($1, n, "_t"); torch[n[2]] = $2 + 0 }
            /^gemm_bf16_1024_t/ { split($1, n, "_t"); tn[n[2]] = $2 + 0 }
            END { for (t in tn) if (torch[t] > 0) printf "gemm_bf16_vs_torch_1024_t%s: %.2f x (terrainnet %.1f, torch %.1f GFLOP/s)\n", t, tn[t] / torch[t], tn[t], torch[t] }' "$out"
rm -f "$out"
