#!/usr/bin/env bash
# Fuzzes gaia's parsers with libFuzzer + ASan + UBSan (clang from Debian), one target after another:
#   scripts/fuzz.sh [SECONDS] [TARGET...]     SECONDS per target (default 600); TARGET in the list below (default all)
# Builds tests/fuzz/CMakeLists.txt into build-fuzz/ (no LibTorch). Each target fuzzes a copy of its seed corpus in
# build-fuzz/corpus-work/<name>, so tests/fuzz/corpus only grows by what someone chooses to add; findings land in
# build-fuzz/artifacts/<name>/, logs in build-fuzz/logs/<name>.log.
# Env: GAIA_FUZZ_FORK=1 keeps fuzzing past a crash (libFuzzer -fork=1 -ignore_crashes=1 ...);
#      GAIA_FUZZ_MAX_LEN (default 8192; the seed corpus holds one larger regression input);
#      GAIA_BUILD_LOCK=FILE holds flock FILE around the build only; GAIA_FUZZ_NICE (default 19) for the runs.
set -euo pipefail
cd "$(dirname "$0")/.."

ALL=(safetensors npy signals_csv config_yaml episode_meta gps_track)
SECONDS_PER=${1:-600}
shift || true
TARGETS=("$@")
[ ${#TARGETS[@]} -eq 0 ] && TARGETS=("${ALL[@]}")
for t in "${TARGETS[@]}"; do
  [[ " ${ALL[*]} " == *" $t "* ]] || { echo "fuzz: unknown target '$t' (have: ${ALL[*]})" >&2; exit 2; }
done

# clang plus the libFuzzer runtime (Debian 12: clang and libclang-rt-14-dev).
fuzzer_rt() { command -v clang++ >/dev/null && [ -f "$(clang++ -print-resource-dir)/lib/linux/libclang_rt.fuzzer-x86_64.a" ]; }
if ! fuzzer_rt; then
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  RT=$(apt-cache search --names-only '^libclang-rt-[0-9]+-dev$' | awk '{print $1}' | sort -V | tail -1)
  if [ -z "$RT" ]; then
    $SUDO apt-get update -qq
    RT=$(apt-cache search --names-only '^libclang-rt-[0-9]+-dev$' | awk '{print $1}' | sort -V | tail -1)
  fi
  echo "fuzz: installing clang ${RT}"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends clang ${RT}
  fuzzer_rt || { echo "fuzz: clang++ has no libFuzzer runtime after installing ${RT}" >&2; exit 1; }
fi

LOCK=()
[ -n "${GAIA_BUILD_LOCK:-}" ] && LOCK=(flock "$GAIA_BUILD_LOCK")
B=build-fuzz
if [ ! -f "$B/build.ninja" ]; then
  "${LOCK[@]}" cmake -S tests/fuzz -B "$B" -G Ninja -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=
fi
"${LOCK[@]}" cmake --build "$B" -j "$(nproc)" --target "${TARGETS[@]/#/fuzz_}"

FORK=()
[ "${GAIA_FUZZ_FORK:-0}" = 1 ] && FORK=(-fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1)
mkdir -p "$B/logs"
SUMMARY=()
for t in "${TARGETS[@]}"; do
  work="$B/corpus-work/$t" art="$B/artifacts/$t/" log="$B/logs/$t.log"
  mkdir -p "$work" "$art"
  # Seeds only: crash-* files are open bugs the ctest replays; fuzzing from them would only find them again.
  find tests/fuzz/corpus/"$t" -maxdepth 1 -type f ! -name 'crash-*' -exec cp -n {} "$work"/ \;
  echo "fuzz: $t for ${SECONDS_PER}s (log $log)"
  touch "$B/logs/$t.start"  # findings of this run are the artifacts newer than this
  rc=0
  nice -n "${GAIA_FUZZ_NICE:-19}" "$B/fuzz_$t" -max_total_time="$SECONDS_PER" -timeout=10 -rss_limit_mb=2048 \
    -max_len="${GAIA_FUZZ_MAX_LEN:-8192}" -print_final_stats=1 -artifact_prefix="$art" "${FORK[@]}" "$work" >"$log" 2>&1 || rc=$?
  # Executions and coverage from libFuzzer's last status line ("#N ... cov: C ft: F"), findings from artifacts.
  last=$(grep -E '^#[0-9]+.*cov: ' "$log" | tail -1 || true)
  execs=$(sed -E 's/^#([0-9]+).*/\1/' <<<"$last")
  cov=$(grep -oE 'cov: [0-9]+' <<<"$last" | awk '{print $2}')
  ft=$(grep -oE 'ft: [0-9]+' <<<"$last" | awk '{print $2}')
  crashes=$(find "$art" -maxdepth 1 -type f -newer "$B/logs/$t.start" \( -name 'crash-*' -o -name 'leak-*' -o -name 'timeout-*' -o -name 'oom-*' \) | wc -l)
  SUMMARY+=("fuzz: $t: ${SECONDS_PER}s, executions ${execs:-?}, coverage ${cov:-?} (features ${ft:-?}), crashes $crashes, exit $rc")
done
printf '%s\n' "${SUMMARY[@]}"
