#!/usr/bin/env bash
# Peer check: does an independent UBO2003 reader open what `btfmrf generate` writes?
# Uses the Ubo2003 class of the btf-extractor package (PyPI), loaded from its source file
# (its package __init__ also imports a Cython extension for another format, which needs an
# old numpy to build; the UBO2003 reader itself is plain Python + simplejpeg).
# Usage: scripts/peers/ubo2003_reader.sh [FILE.zip]   (default: generates sponge, size 32)
set -euo pipefail
cd "$(dirname "$0")/../.."
work="${TMPDIR:-/tmp}/btfmrf-peer-ubo2003"
mkdir -p "$work"
if [ ! -x "$work/venv/bin/python" ]; then
  python3 -m venv "$work/venv"
  "$work/venv/bin/pip" install -q numpy simplejpeg imageio "nptyping<2" poetry-core
fi
if [ ! -f "$work/src/ubo2003.py" ]; then
  "$work/venv/bin/pip" download -q --no-deps --no-build-isolation btf-extractor==1.7.0 -d "$work/dl"
  mkdir -p "$work/src"
  tar -xzf "$work"/dl/btf_extractor-1.7.0.tar.gz -C "$work/src" --strip-components=2 \
    btf_extractor-1.7.0/btf_extractor/ubo2003.py
fi
zip="${1:-}"
if [ -z "$zip" ]; then
  cargo build --release --locked --bin btfmrf -q
  zip="$work/sponge32.zip"
  target/release/btfmrf generate sponge --size 32 --out "$zip" --quiet >/dev/null
fi
"$work/venv/bin/python" scripts/peers/ubo2003_reader.py "$work/src/ubo2003.py" "$zip"
