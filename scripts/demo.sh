#!/usr/bin/env bash
# The main job on the built-in default swatch: bake a plain weave from a 32-light dome at 64²,
# fit a 6-coefficient PTM (the default model: logistic link, hemispherical (u, v), MIP levels),
# render a GPU preview that evaluates K, and print where each file went.
# Idempotent: runs the setup, builds what is missing, overwrites out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
out=${1:-out/demo}
mkdir -p "$out"
cargo build -q --bin ptm
ptm=${CARGO_TARGET_DIR:-target}/debug/ptm

"$ptm" bake --swatch builtin:plain-weave --res 64 --dirs 32 -o "$out/samples.exr"
"$ptm" fit "$out/samples.exr" --basis ptm6 -o "$out/weave.ptm.exr"
"$ptm" preview --ptm "$out/weave.ptm.exr" -o "$out/preview.png"

echo
echo "samples (K per light):  $out/samples.exr"
echo "light dome (.lp):       $out/samples.lp"
echo "occlusion PTM (ptm6, logistic): $out/weave.ptm.exr"
echo "GPU preview:            $out/preview.png"
