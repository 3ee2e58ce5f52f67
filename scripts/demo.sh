#!/usr/bin/env bash
# Quick start, command 1: install dependencies, build, and run `gaia demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh
exec "${GAIA_BUILD_DIR:-build}/gaia" demo "$@"
