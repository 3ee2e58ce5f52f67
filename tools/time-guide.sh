#!/usr/bin/env bash
# Times every command of docs/your-drives.md's walkthrough block at the default size, on the real clips it names
# (docs/benchmarks.md, "The guide, step by step"). Training commands run STEPS steps (default 30) and their full
# length is extrapolated from the time per step after the first; everything else runs as written.
#
#   tools/time-guide.sh REAL_DIR OUT_DIR [GAIA_BINARY]
set -euo pipefail
REAL=${1:?usage: time-guide.sh REAL_DIR OUT_DIR [GAIA]}
OUT=${2:?usage: time-guide.sh REAL_DIR OUT_DIR [GAIA]}
GAIA=$(realpath "${3:-build/gaia}")
ROOT=$(cd "$(dirname "$0")/.." && pwd)
STEPS=${STEPS:-30}
mkdir -p "$OUT"
for c in highway-sunny-720p25.mp4 night-rural-1080p30.mp4; do ln -sf "$(realpath "$REAL/$c")" "$OUT/$c"; done
# The block after the guide marker, continuation lines joined.
awk '/<!-- guide:/{m=1} m&&/^```sh/{b=1;next} b&&/^```/{exit} b' "$ROOT/docs/your-drives.md" | sed -e ':a' -e '/\\$/N; s/\\\n//; ta' > "$OUT/commands.txt"
cd "$OUT"
while read -r line; do
  args=${line#gaia }
  extra=""
  case "$args" in "tokenizer train"*|"world train"*) extra="--steps $STEPS --val-every 0" ;; esac
  start=$(date +%s.%N)
  eval "\"$GAIA\" $args $extra" > "step.log" 2>&1 < /dev/null || { echo "failed: $line"; cat step.log; exit 1; }
  end=$(date +%s.%N)
  echo "$(echo "$end - $start" | bc) s	$line ${extra}" | tee -a times.tsv
done < commands.txt
