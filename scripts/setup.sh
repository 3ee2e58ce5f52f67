#!/usr/bin/env bash
# Installs everything gaia needs from Debian 12 packages. Idempotent: a second run installs nothing.
set -euo pipefail

PKGS=(
  build-essential cmake ninja-build ccache pkg-config
  libtorch-dev                 # LibTorch 1.13 (CPU); find_package(Torch)
  libgloo-dev                  # Gloo's headers: c10d's CPU process group (data-parallel training)
  libopenblas0-pthread         # fast BLAS for LibTorch's matrix products (the default reference BLAS is ~10x slower)
  libopencv-dev                # image / video I/O (FFmpeg backend)
  ffmpeg                       # video codecs used by OpenCV's FFmpeg backend
  libavformat-dev              # a container's presented duration (cut clips hold more packets than they show)
  libcli11-dev                 # command-line parsing
  libyaml-cpp-dev              # configs
  nlohmann-json3-dev           # safetensors headers, JSONL metrics
  libpugixml-dev               # GPX tracks
  libcpp-httplib-dev           # gaia sim serve (HTTP on loopback)
  libfmt-dev libspdlog-dev     # formatting and logging
  libgtest-dev libgmock-dev libbenchmark-dev
  libsentencepiece-dev         # T5's tokenizer (SentencePiece) for the frozen text encoder (§2.1)
  liblzma-dev libzstd-dev      # xz -9 and zstd -19 as floors in world-model evaluation (bits per token)
  chromium                     # headless browser: the report test renders gaia report pages and checks screenshots
  pybind11-dev python3-dev     # the `gaia` Python module (python/, docs/python.md)
  python3-numpy python3-pytest # ... its arrays and its tests
  python3-venv python3-setuptools python3-wheel python3-pip  # ... `pip install .` of a checkout, tested in a venv
  python3-torch                # the PyTorch policy example and the Python peers of tests and benchmarks
)

missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "setup: all packages present"
fi
