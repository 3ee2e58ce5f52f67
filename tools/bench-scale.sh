#!/usr/bin/env bash
# docs/benchmarks.md, "Mixed precision and data-parallel ranks on the CPU": world-model training steps and a rollout
# at the default size, fp32 against bf16, one process against --nproc 2, gradients averaged during the backward pass
# against after it, back to back on the same tokens; then "Training memory": gaia plan's peak against the measured.
#
#   tools/bench-scale.sh OUT_DIR [GAIA_BINARY]      (STEPS=30 training steps per run)
set -euo pipefail
OUT=${1:?usage: bench-scale.sh OUT_DIR [GAIA]}
GAIA=$(realpath "${2:-build/gaia}")
ROOT=$(cd "$(dirname "$0")/.." && pwd)
STEPS=${STEPS:-30}
mkdir -p "$OUT"
cd "$OUT"
if [ ! -f tokens/dataset.json ]; then
  "$GAIA" synth --episodes 8 --seconds 20 --out synth > /dev/null
  "$GAIA" tokenize synth --tokenizer "$ROOT/models/tokenizer.safetensors" --out tokens > /dev/null
fi
# Median tokens/s of a run's steps after the first two (warm-up).
median_tps() {
  python3 -c "import json,statistics,sys; r=[json.loads(l)['tokens_per_s'] for l in open(sys.argv[1])][2:]; print(round(statistics.median(r)))" "$1"
}
train() {  # NAME FLAGS... (CAP: a command prefix, e.g. env VAR=VALUE)
  local name=$1; shift
  rm -rf "run-$name"
  ${CAP:-} "$GAIA" world train tokens --steps "$STEPS" --val-every 0 --out "run-$name" "$@" > "run-$name.log" 2>&1
  echo "$name $(median_tps "run-$name/metrics.jsonl")"
}
echo "instruction set: $(grep -o -m1 -w 'avx512_bf16\|avx512f\|avx2' /proc/cpuinfo | head -1)"
echo "world train, tokens/s (median of steps 3..$STEPS)"
train fp32 --precision fp32
train bf16 --precision bf16
# The same two with LibTorch's kernels capped at AVX2, as a CPU without AVX-512 runs them: there bf16 has no
# instructions of its own and falls back to fp32 (saying so in the run's log).
CAP="env ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2" train fp32-avx2 --precision fp32
CAP="env ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2" train bf16-avx2 --precision bf16
grep -h "no bf16 instructions" run-bf16-avx2.log || true
train nproc1 --threads 2
train nproc2 --nproc 2
train nproc2-no-overlap --nproc 2 --no-overlap
echo "generate, 16 frames x 4 futures from an 8-frame prompt"
for p in fp32 bf16; do
  /usr/bin/time -f "$p %e s" "$GAIA" generate tokens --world "$ROOT/models/world.safetensors" --episode 0 \
    --prompt-frames 8 --frames 16 --futures 4 --precision "$p" --out "gen-$p" 2>&1 | grep -E "frames/s|^$p "
done
echo "world train memory: measured peak above the start of training, and gaia plan's figure"
for b in 2 4 8; do
  rm -rf mem
  echo "default, batch $b: $("$GAIA" world train tokens --steps 3 --val-every 0 --set world.batch_size=$b --threads 2 \
    --out mem 2>&1 | grep -o 'the peak was.*beyond')"
done
python3 - <<'PY'  # random ids of a 4x8 grid, K = 64, as an int64 .npy (standard library only)
import array, random
random.seed(0)
header = "{'descr': '<i8', 'fortran_order': False, 'shape': (160, 4, 8), }"
header += " " * (118 - len(header)) + "\n"
with open("tiny.npy", "wb") as f:
    f.write(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode())
    f.write(array.array("q", [random.randrange(64) for _ in range(160 * 4 * 8)]).tobytes())
PY
rm -rf mem
echo "tiny, batch 4: $("$GAIA" world train tiny.npy --grid 4x8 --codebook-size 64 --config "$ROOT/configs/tiny.yaml" \
  --steps 3 --val-every 0 --threads 2 --out mem 2>&1 | grep -o 'the peak was.*beyond')"
