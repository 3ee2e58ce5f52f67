#!/usr/bin/env bash
# The figures of models/MODEL_CARD.md for a candidate release beside the shipped one, on the candidate's held-out
# split: a run of `gaia train-all --data CLIPS --manifest FILE` (its data/, tokenizer/, tokens/, world-calibrated/,
# probe-realism/). Each world model is scored on tokens of its own tokenizer (a release with new codes has its own):
# the shipped models' tokens of the same data are made (RUN/tokens-shipped) after the candidate's figures. Every step
# skips what its output already holds, so a killed run picks up where it stopped.
#
#   tools/release-figures.sh RUN OUT [GAIA_BINARY]
# Knobs (environment): THREADS (2), SEED (2), MODELS (the repository's models/).
set -euo pipefail
RUN=${1:?usage: release-figures.sh RUN OUT [GAIA]}
OUT=${2:?usage: release-figures.sh RUN OUT [GAIA]}
GAIA=${3:-build/gaia}
MODELS=${MODELS:-$(cd "$(dirname "$0")/.." && pwd)/models}
SEED=${SEED:-2}
T=(--threads "${THREADS:-2}")
mkdir -p "$OUT"
log() { echo "[$(date +%H:%M:%S)] $*" | tee -a "$OUT/figures.log"; }
step() {  # step OUTPUT COMMAND...: run the command unless OUTPUT exists
  local out=$1; shift
  if [ -e "$out" ]; then log "kept $out"; return; fi
  log "$*"
  "$@"
}

# The candidate's models and the shipped ones, each with the tokens of its own tokenizer.
declare -A TOK=([new]="$RUN/tokenizer/tokenizer.safetensors" [shipped]="$MODELS/tokenizer.safetensors")
declare -A WORLD=([new]="$RUN/world-calibrated/world.safetensors" [shipped]="$MODELS/world.safetensors")
declare -A REALISM=([new]="$RUN/probe-realism/probe-realism.safetensors" [shipped]="$MODELS/probe-realism.safetensors")
declare -A TOKENS=([new]="$RUN/tokens" [shipped]="$RUN/tokens-shipped")
declare -A DECODER=([new]="$RUN/decoder/decoder.safetensors" [shipped]="$MODELS/decoder.safetensors")
# The candidate's figures first: they decide whether it ships.
for m in new shipped; do
  [ "$m" = shipped ] && step "$RUN/tokens-shipped/dataset.json" "$GAIA" tokenize "$RUN/data" --tokenizer "${TOK[shipped]}" \
    --mirror "${T[@]}" --out "$RUN/tokens-shipped"
  # Tokenizer: held-out real clips (median and worst clip, per clip and condition) and procedural drives.
  step "$OUT/$m-tokenizer.json" "$GAIA" tokenizer eval "$RUN/data" --tokenizer "${TOK[$m]}" --max-frames 1024 "${T[@]}" \
    --out "$OUT/$m-tokenizer.json"
  # World model: held-out bits per image token against xz -9, real and procedural apart.
  step "$OUT/$m-world-real/eval.json" "$GAIA" world eval "${TOKENS[$m]}" --world "${WORLD[$m]}" --footage real \
    --max-windows 128 "${T[@]}" --out "$OUT/$m-world-real"
  step "$OUT/$m-world-procedural/eval.json" "$GAIA" world eval "${TOKENS[$m]}" --world "${WORLD[$m]}" \
    --footage procedural --max-windows 64 "${T[@]}" --out "$OUT/$m-world-procedural"
  # Realism probe on held-out frames, raw and read through the tokenizer.
  step "$OUT/$m-realism.txt" sh -c "\"$GAIA\" probe eval \"$RUN/data\" --probe \"${REALISM[$m]}\" --tokenizer \"${TOK[$m]}\" \
    --examples 512 ${T[*]} > \"$OUT/$m-realism.txt.part\" && mv \"$OUT/$m-realism.txt.part\" \"$OUT/$m-realism.txt\""
  # Real prompts: futures read as real, FD-probe, steering read back by the dynamics probe and by ego-motion.
  step "$OUT/$m-real/eval.json" "$GAIA" eval "${TOKENS[$m]}" --world "${WORLD[$m]}" --tokenizer "${TOK[$m]}" \
    --prompt-footage real --realism-probe "${REALISM[$m]}" --only action,futures --prompts 8 --action-guidance 16 \
    --seed "$SEED" "${T[@]}" --out "$OUT/$m-real"
  # Procedural prompts: steering against the counterfactual replay, and text at the shipped scales.
  step "$OUT/$m-procedural/eval.json" "$GAIA" eval "${TOKENS[$m]}" "$RUN/data" --world "${WORLD[$m]}" \
    --tokenizer "${TOK[$m]}" --prompt-footage procedural --only action --prompts 16 --action-guidance 16 \
    --seed "$SEED" "${T[@]}" --out "$OUT/$m-procedural"
  step "$OUT/$m-text/eval.json" "$GAIA" eval "${TOKENS[$m]}" "$RUN/data" --world "${WORLD[$m]}" \
    --tokenizer "${TOK[$m]}" --only text --seed "$SEED" "${T[@]}" --out "$OUT/$m-text"
  # The video decoder against the tokenizer's own on held-out real clips, 10 DDIM steps.
  step "$OUT/$m-decoder-real/eval.json" "$GAIA" decoder eval "$RUN/data" --decoder "${DECODER[$m]}" \
    --tokenizer "${TOK[$m]}" --footage real --clips 4 --token-frames 4 --steps 10 "${T[@]}" --out "$OUT/$m-decoder-real"
done
log "done: $OUT"
