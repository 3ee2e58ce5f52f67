#!/usr/bin/env bash
# The GPU check of docs/scale.md, in one call on a CUDA machine that has PyTorch and nothing else:
#   1. builds gaia without video (-DGAIA_WITH_VIDEO=OFF) against the LibTorch inside that PyTorch, with the few
#      -dev packages it needs unpacked from DEPS (Debian packages, fetched beforehand where a network is);
#   2. runs the model tests on CUDA (GAIA_TEST_DEVICE=cuda);
#   3. benchmarks world-model training at bf16 for a ~0.3B and a ~1B configuration (tokens/s, and model FLOPs
#      utilisation from `gaia plan`'s FLOPs per token), a rollout (frames/s) and fp32 against bf16.
# Everything it prints goes to OUT/gpu-check.log as well; the figures to OUT/gpu-check.json.
#
#   scripts/gpu-check.sh --fetch DEPS        on a Debian 12 machine with a network: download the packages
#   scripts/gpu-check.sh DEPS OUT            on the GPU machine (PEAK_TFLOPS: the GPU's dense bf16 peak, default
#                                            989, an H100/H200 SXM; CHECK_DEVICE=cpu: a dry run without a GPU,
#                                            with TORCH_PREFIX and PYTHON naming a LibTorch and a Python)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PKGS=(libyaml-cpp-dev libyaml-cpp0.7 nlohmann-json3-dev libfmt-dev libfmt9 libcli11-dev libgloo-dev liblzma-dev
      liblzma5 libzstd-dev libzstd1 libgtest-dev pkgconf pkgconf-bin libpkgconf3)

if [ "${1:-}" = "--fetch" ]; then
  DEPS=${2:?usage: gpu-check.sh --fetch DEPS}
  mkdir -p "$DEPS"
  (cd "$DEPS" && apt-get download "${PKGS[@]}")
  du -sh "$DEPS"
  exit 0
fi
DEPS=$(realpath "${1:?usage: gpu-check.sh DEPS OUT}")
OUT=$(realpath -m "${2:?usage: gpu-check.sh DEPS OUT}")
mkdir -p "$OUT"
exec > >(tee "$OUT/gpu-check.log") 2>&1
PEAK=${PEAK_TFLOPS:-989}
DEV=${CHECK_DEVICE:-cuda}
PY=${PYTHON:-python3}  # the Python that holds PyTorch (and NumPy)
T0=$(date +%s)
stamp() { echo "== $(( $(date +%s) - T0 )) s: $*"; }

stamp "packages from $DEPS"
PREFIX=/tmp/gaia-deps
mkdir -p "$PREFIX"
for f in "$DEPS"/*.deb; do dpkg -x "$f" "$PREFIX"; done
export PATH="$PREFIX/usr/bin:$PATH"
export PKG_CONFIG_PATH="$PREFIX/usr/lib/x86_64-linux-gnu/pkgconfig:$PREFIX/usr/share/pkgconfig"
export PKG_CONFIG_SYSROOT_DIR="$PREFIX"
export LD_LIBRARY_PATH="$PREFIX/usr/lib/x86_64-linux-gnu:${LD_LIBRARY_PATH:-}"

stamp "build against PyTorch's LibTorch"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
TORCH_PREFIX=${TORCH_PREFIX:-$("$PY" -c 'import torch; print(torch.utils.cmake_prefix_path)')}
"$PY" -c 'import torch; print("torch", torch.__version__, "CUDA", torch.version.cuda, "cuDNN", torch.backends.cudnn.version())'
BUILD=/tmp/gaia-build-cuda
cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release -DGAIA_WITH_VIDEO=OFF \
  -DCMAKE_PREFIX_PATH="$TORCH_PREFIX;$PREFIX/usr;$PREFIX/usr/lib/x86_64-linux-gnu/cmake"
cmake --build "$BUILD" -j "$(nproc)"
GAIA="$BUILD/gaia"

stamp "model tests on $DEV"
(cd "$BUILD" && GAIA_TEST_DEVICE=$DEV ctest -j 4 --output-on-failure --timeout 300) || echo "TESTS FAILED"

stamp "benchmarks"
W=/tmp/gaia-gpu-bench
mkdir -p "$W"
# Random tokens of the default grid (9 x 16, K = 1024): the speed of a step does not depend on what they show.
"$PY" - "$W/tokens.npy" <<'PY'
import sys, numpy as np
np.save(sys.argv[1], np.random.default_rng(0).integers(0, 1024, size=(4000, 9, 16), dtype=np.int64))
PY
bench() {  # NAME STEPS FLAGS...: world train, median tokens/s of the steps after the first three
  local name=$1 steps=$2; shift 2
  "$GAIA" world train "$W/tokens.npy" --grid 9x16 --codebook-size 1024 --steps "$steps" --val-every 0 \
    --device "$DEV" --out "$W/$name" "$@" > "$W/$name.log" 2>&1 || { tail -3 "$W/$name.log"; return 0; }
  local flops
  flops=$("$GAIA" plan "$@" --json | "$PY" -c 'import json,sys; print(json.load(sys.stdin)["world_flops_per_token_with_attn"])')
  "$PY" - "$W/$name/metrics.jsonl" "$flops" "$PEAK" "$name" "$OUT/gpu-check.json" <<'PY'
import json, statistics, sys
path, flops, peak, name, out = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4], sys.argv[5]
tps = statistics.median([json.loads(l)["tokens_per_s"] for l in open(path)][3:])
mfu = tps * flops / (peak * 1e12)
print(f"{name}: {tps:,.0f} tokens/s, {flops / 1e9:.2f} GFLOP/token, MFU {100 * mfu:.1f}% of {peak:.0f} TFLOP/s")
try: results = json.load(open(out))
except Exception: results = {}
results[name] = {"tokens_per_s": tps, "flops_per_token": flops, "mfu": mfu}
json.dump(results, open(out, "w"), indent=2)
PY
}
S03="--set world.d_model=1024 --set world.n_layers=24 --set world.n_heads=16 --set world.batch_size=32"
S1B="--set world.d_model=2048 --set world.n_layers=20 --set world.n_heads=16 --set world.batch_size=16"
if [ "$DEV" = cpu ]; then  # a dry run: the same commands on models a CPU steps through in seconds
  S03="--set world.d_model=64 --set world.n_layers=2 --set world.n_heads=4 --set world.batch_size=2"
  S1B="--set world.d_model=96 --set world.n_layers=2 --set world.n_heads=4 --set world.batch_size=2"
fi
# shellcheck disable=SC2086
bench world-0.3b-bf16 20 $S03 --precision bf16
# shellcheck disable=SC2086
bench world-0.3b-fp32 12 $S03 --precision fp32
# shellcheck disable=SC2086
bench world-1b-bf16 16 $S1B --precision bf16

stamp "rollout"
for p in fp32 bf16; do
  "$GAIA" generate "$W/tokens.npy" --grid 9x16 --codebook-size 1024 --world "$W/world-0.3b-bf16/world.safetensors" \
    --prompt-frames 4 --frames 32 --futures 16 --device "$DEV" --precision "$p" --out "$W/gen-$p" | grep frames/s || true
done
stamp "done"
