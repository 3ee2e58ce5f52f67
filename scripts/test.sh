#!/usr/bin/env bash
# Quick start, command 2: install dependencies, build, and run the whole test suite (CI runs this).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh
cd "${GAIA_BUILD_DIR:-build}"
ctest --output-on-failure -j "$(nproc)" --timeout 900
