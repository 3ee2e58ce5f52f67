#!/usr/bin/env bash
# Leave-one-clip-out measurements on real footage (docs/evaluation.md, "On real footage"): for each real clip held
# out in turn,
#   - the tokenizer fine-tuned with real frames in half of each batch: PSNR/SSIM on the held-out clip and on
#     held-out procedural drives;
#   - the realism probe (real vs procedural) trained on the other clips and procedural drives, scored on the held-out
#     clip, then reading futures of that clip's prompt from the shipped world model and from one fine-tuned on the
#     other clips' tokens;
#   - the world model on real tokens: held-out bits/token against xz -9, shipped and fine-tuned.
# Every stage skips what its output already holds, so a killed run picks up where it stopped.
#
#   tools/real-clips-study.sh REAL_DIR OUT_DIR [GAIA_BINARY]
# REAL_DIR holds highway-sunny-720p25.mp4, night-rural-1080p30.mp4, kitti-residential-gray-10hz/ and
# kitti-raw-0002-color-10f/. Knobs (environment): TOK_STEPS (400), PROBE_STEPS (600), WORLD_STEPS (300), THREADS (2).
set -euo pipefail
REAL=${1:?usage: real-clips-study.sh REAL_DIR OUT_DIR [GAIA]}
OUT=${2:?usage: real-clips-study.sh REAL_DIR OUT_DIR [GAIA]}
GAIA=${3:-build/gaia}
MODELS=$(cd "$(dirname "$0")/.." && pwd)/models
TOK_STEPS=${TOK_STEPS:-400}
PROBE_STEPS=${PROBE_STEPS:-600}
WORLD_STEPS=${WORLD_STEPS:-300}
T="--threads ${THREADS:-2}"
mkdir -p "$OUT"
log() { echo "[$(date +%H:%M:%S)] $*" | tee -a "$OUT/study.log"; }
gaia() { "$GAIA" "$@"; }

# 1. The clips as one dataset (estimated motion where no signals exist), procedural drives beside them.
if [ ! -f "$OUT/real/.done" ]; then
  rm -rf "$OUT/real"
  gaia ingest "$REAL/highway-sunny-720p25.mp4" --id highway --motion video --meta weather=clear --meta time_of_day=day --out "$OUT/real" $T
  gaia ingest "$REAL/night-rural-1080p30.mp4" --id night --motion video --meta time_of_day=night --out "$OUT/real" $T
  gaia ingest "$REAL/kitti-residential-gray-10hz" --fps 10 --poses "$REAL/kitti-residential-gray-10hz/poses.txt" \
      --id kitti-res --out "$OUT/real" $T
  gaia ingest "$REAL/kitti-raw-0002-color-10f/2011_09_26/2011_09_26_drive_0002_sync" --id kitti-raw --out "$OUT/real" $T
  touch "$OUT/real/.done"
fi
[ -f "$OUT/synth/.done" ] || { rm -rf "$OUT/synth"; gaia synth --episodes 24 --seconds 20 --seed 5 --out "$OUT/synth" $T; touch "$OUT/synth/.done"; }
if [ ! -f "$OUT/tokens/.done" ]; then
  gaia tokenize "$OUT/real" --tokenizer "$MODELS/tokenizer.safetensors" --mirror --out "$OUT/tokens" $T
  touch "$OUT/tokens/.done"
fi

# A dataset of links: linked DIR DATASET [EPISODE...] (every episode of DATASET when none is named).
linked() {
  local dir=$1 src=$2; shift 2
  rm -rf "$dir"; mkdir -p "$dir/episodes"
  cp "$src/dataset.json" "$dir/"
  local eps=("$@")
  [ ${#eps[@]} -gt 0 ] || eps=($(ls "$src/episodes"))
  for e in "${eps[@]}"; do ln -s "$(cd "$src/episodes/$e" && pwd)" "$dir/episodes/$e"; done
}
# Every episode of the datasets, with a split holding out the named ones: mixed DIR HOLD_OUT... -- DATASET...
mixed() {
  local dir=$1; shift
  local hold=()
  while [ "$1" != "--" ]; do hold+=(--hold-out "$1"); shift; done
  shift
  linked "$dir" "$1"
  shift
  for src in "$@"; do for e in $(ls "$src/episodes"); do ln -s "$(cd "$src/episodes/$e" && pwd)" "$dir/episodes/$e"; done; done
  gaia data split "$dir" "${hold[@]}" --val-fraction 0 > /dev/null  # nothing else held out: every other clip trains
}

RESULTS="$OUT/results.jsonl"
touch "$RESULTS"
record() { echo "$1" >> "$RESULTS"; log "$1"; }

for clip in highway night kitti-res kitti-raw; do
  F="$OUT/fold-$clip"
  mkdir -p "$F"
  [ -f "$F/mix/split.json" ] || mixed "$F/mix" "$clip" synth-s5-e00022 synth-s5-e00023 -- "$OUT/real" "$OUT/synth"

  # Tokenizer: shipped, and fine-tuned with half of each batch real (footage balancing), on the held-out clip and
  # on two held-out procedural drives (one-episode-kind datasets of links, so each is scored alone).
  if ! grep -q "\"tokenizer\".*\"fold\": \"$clip\"" "$RESULTS"; then
    [ -f "$F/tok/tokenizer.safetensors" ] || gaia tokenizer train "$F/mix" --init "$MODELS/tokenizer.safetensors" \
        --steps "$TOK_STEPS" --val-every 0 --set 'data.balance_tokenizer=[footage]' --set data.balance_exponent=1 \
        --set tokenizer.lr=1e-4 --set tokenizer.final_lr=1e-5 --set tokenizer.warmup_steps=20 \
        --set tokenizer.disc_start=1000000000 --set tokenizer.refine_blocks=2 --set tokenizer.token_blocks=2 \
        --set tokenizer.ema_decay=0.999 --out "$F/tok" $T
    linked "$F/eval-clip" "$OUT/real" "$clip"
    linked "$F/eval-synth" "$OUT/synth" synth-s5-e00022 synth-s5-e00023
    for name in shipped fine-tuned; do
      w=$([ $name = shipped ] && echo "$MODELS/tokenizer.safetensors" || echo "$F/tok/tokenizer.safetensors")
      gaia tokenizer eval "$F/eval-clip" --tokenizer "$w" --max-frames 512 --out "$F/tokeval-$name-clip.json" $T > /dev/null
      gaia tokenizer eval "$F/eval-synth" --tokenizer "$w" --max-frames 256 --out "$F/tokeval-$name-synth.json" $T > /dev/null
      record "{\"tokenizer\": \"$name\", \"fold\": \"$clip\", \"held_out_clip\": $(tr -d '\n ' < "$F/tokeval-$name-clip.json"), \"held_out_procedural\": $(tr -d '\n ' < "$F/tokeval-$name-synth.json")}"
    done
  fi
  [ "$clip" = kitti-raw ] && continue  # 10 frames: too short a prompt for the world model's 8 steps

  # Realism probe, leave this clip out.
  [ -f "$F/realism/probe-realism.safetensors" ] || gaia probe train realism "$F/mix" --tokenizer "$MODELS/tokenizer.safetensors" \
      --steps "$PROBE_STEPS" --batch-size 32 --val-every 0 --out "$F/realism" $T
  if ! grep -q "\"realism\".*\"fold\": \"$clip\"" "$RESULTS"; then
    gaia probe eval "$F/mix" --probe "$F/realism/probe-realism.safetensors" --tokenizer "$MODELS/tokenizer.safetensors" \
        --examples 400 --out "$F/realism-eval" $T > /dev/null
    record "{\"realism\": \"held-out\", \"fold\": \"$clip\", \"eval\": $(tr -d '\n ' < "$F/realism-eval/probe_eval.json")}"
  fi

  # World model on real tokens: the other clips' tokens (and their mirror images), fine-tuning the shipped model.
  [ -f "$F/tokens/split.json" ] || { linked "$F/tokens" "$OUT/tokens"; gaia data split "$F/tokens" --hold-out "$clip" > /dev/null; }
  [ -f "$F/world/world.safetensors" ] || gaia world train "$F/tokens" --init "$MODELS/world.safetensors" \
      --steps "$WORLD_STEPS" --val-every 0 --set world.lr=1e-4 --set world.warmup_steps=20 --out "$F/world" $T
  for name in shipped fine-tuned; do
    w=$([ $name = shipped ] && echo "$MODELS/world.safetensors" || echo "$F/world/world.safetensors")  # fixed steps: the held-out clip never picks a checkpoint
    if ! grep -q "\"world\": \"$name\", \"fold\": \"$clip\"" "$RESULTS"; then
      gaia world eval "$F/tokens" --world "$w" --out "$F/worldeval-$name" $T > /dev/null
      record "{\"world\": \"$name\", \"fold\": \"$clip\", \"eval\": $(tr -d '\n ' < "$F/worldeval-$name/eval.json")}"
    fi
    if ! grep -q "\"futures\": \"$name\", \"fold\": \"$clip\"" "$RESULTS"; then
      gaia generate "$OUT/tokens" --episode "$clip" --world "$w" --tokenizer "$MODELS/tokenizer.safetensors" \
          --frames 16 --futures 4 --out "$F/gen-$name" $T > /dev/null
      gaia probe read "$F/gen-$name/rollout.safetensors" --probe "$F/realism/probe-realism.safetensors" \
          --tokenizer "$MODELS/tokenizer.safetensors" --out "$F/read-$name" $T > /dev/null
      record "{\"futures\": \"$name\", \"fold\": \"$clip\", \"read\": $(tr -d '\n ' < "$F/read-$name/probe_read.json")}"
    fi
  done
done
log "done: $RESULTS"
