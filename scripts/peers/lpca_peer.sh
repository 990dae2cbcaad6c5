#!/usr/bin/env bash
# Peer check: our local PCA (Rust, faer) against a numpy reference of the same algorithm
# (Gram-matrix PCA), on the same data, timed side by side in one run.
# Data: generated stones 64x64 (n = 4096 texels), every third Bonn view and light
# (27 x 27 x RGB: d = 2187), exported by examples/lpca_peer.rs as float32 .npy.
# Both fit K = 32 clusters, C = 8 components, exactly 10 iterations; each reports the median
# of RUNS fits (data already in memory) and its final mean squared reconstruction error.
# Usage: scripts/peers/lpca_peer.sh [RUNS] [SEEDS...]   (default: 3 runs, seeds 1 2 3)
set -euo pipefail
cd "$(dirname "$0")/../.."
work="${TMPDIR:-/tmp}/btfmrf-peer-lpca"
mkdir -p "$work"
if [ ! -x "$work/venv/bin/python" ]; then
  python3 -m venv "$work/venv"
  "$work/venv/bin/pip" install -q numpy scikit-learn
fi
runs="${1:-3}"
shift || true
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(1 2 3)
cargo build --release --locked --example lpca_peer -q
echo "machine: $(nproc) cores, $(uname -m); load: $(cut -d' ' -f1-3 /proc/loadavg)"
for seed in "${seeds[@]}"; do
  target/release/examples/lpca_peer "$work" "$runs" "$seed"
  "$work/venv/bin/python" scripts/peers/lpca_peer.py "$work/data.npy" "$runs" "$seed"
done
