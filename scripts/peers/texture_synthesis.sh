#!/usr/bin/env bash
# Peer check: our MRF synthesis against the non-parametric `texture-synthesis` crate (Embark,
# 0.8), enlarging the same measured image to 1024 x 1024. The peer is built in a scratch crate
# under $TMPDIR (it is not a dependency of btfmrf). Inputs: the generated 256 x 256 sponge,
# view (0, 0), light (45, 0), then each photograph in ../shared/data/textures (the default
# 2D CAR model with its structure exemplar, seed 1). Prints both times and the texture judge's
# figures for both against the measured image, with the judge's reference levels
# (examples/fidelity.rs). About a minute of the peer per image on 2 cores.
# Usage: scripts/peers/texture_synthesis.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
work="${TMPDIR:-/tmp}/btfmrf-peer-texture-synthesis"
mkdir -p "$work/peer/src"
cat > "$work/peer/Cargo.toml" <<'TOML'
[package]
name = "peer"
version = "0.1.0"
edition = "2021"
[dependencies]
texture-synthesis = "0.8"
TOML
cat > "$work/peer/src/main.rs" <<'RUST'
use std::time::Instant;
fn main() -> Result<(), texture_synthesis::Error> {
    let args: Vec<String> = std::env::args().collect();
    let start = Instant::now();
    let session = texture_synthesis::Session::builder()
        .add_example(&args[1])
        .output_size(texture_synthesis::Dims::square(1024))
        .seed(1)
        .build()?;
    let image = session.run(None);
    println!("texture-synthesis: {:.2} s", start.elapsed().as_secs_f64());
    image.save(&args[2])?;
    Ok(())
}
RUST
(cd "$work/peer" && cargo build --release -q)
cargo build --release --locked -q --bin btfmrf --example fidelity
btfmrf=target/release/btfmrf
[ -f "$work/sponge256.zip" ] || "$btfmrf" generate sponge --size 256 --out "$work/sponge256.zip" -q
python3 - "$work" <<'PY'
import sys, zipfile
work = sys.argv[1]
with zipfile.ZipFile(f"{work}/sponge256.zip") as z:
    name = next(n for n in z.namelist() if "tl045 pl000 tv000 pv000" in n)
    open(f"{work}/measured.jpg", "wb").write(z.read(name))
PY
echo "machine: $(nproc) cores, $(uname -m); load: $(cut -d' ' -f1-3 /proc/loadavg)"
"$work/peer/target/release/peer" "$work/measured.jpg" "$work/texture-synthesis.png"
"$btfmrf" analyze "$work/sponge256.zip" --model 2dcar --out "$work/sponge256.btfm" -q --json |
  python3 -c 'import json,sys; print("btfmrf analyze: %.2f s" % json.load(sys.stdin)["analysis_seconds"])'
"$btfmrf" synthesize "$work/sponge256.btfm" --size 1024 --view 0,0 --light 45,0 --seed 1 \
  --out "$work/btfmrf.png" -q --json |
  python3 -c 'import json,sys; print("btfmrf synthesize: %.3f s" % json.load(sys.stdin)["synthesis_seconds"])'
target/release/examples/fidelity "$work/measured.jpg" "$work/texture-synthesis.png" "$work/btfmrf.png"
for photo in ../shared/data/textures/*.png; do
  [ -f "$photo" ] || continue
  name=$(basename "$photo" .png)
  echo "== $name"
  "$work/peer/target/release/peer" "$photo" "$work/texture-synthesis-$name.png"
  "$btfmrf" analyze "$photo" --out "$work/$name.btfm" -q
  "$btfmrf" synthesize "$work/$name.btfm" --size 1024 --seed 1 --out "$work/btfmrf-$name.png" -q --json |
    python3 -c 'import json,sys; print("btfmrf synthesize: %.3f s" % json.load(sys.stdin)["synthesis_seconds"])'
  target/release/examples/fidelity "$photo" "$work/texture-synthesis-$name.png" "$work/btfmrf-$name.png"
done
