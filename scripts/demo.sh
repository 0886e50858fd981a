#!/usr/bin/env bash
# The main job on the built-in default swatch: bake a plain weave from a 32-light dome at 256²
# with its companion maps,
# fit a 6-coefficient PTM (the default model: logistic link, hemispherical (u, v), MIP levels),
# render a GPU preview that evaluates K, then the weave on the built-in drape, and print where
# each file went.
# Idempotent: runs the setup, builds what is missing, overwrites out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
out=${1:-out/demo}
mkdir -p "$out"
cargo build -q --bin ptm
ptm=${CARGO_TARGET_DIR:-target}/debug/ptm

"$ptm" bake --swatch builtin:plain-weave --res 256 --dirs 32 --maps -o "$out/samples.exr"
"$ptm" fit "$out/samples.exr" --basis ptm6 -o "$out/weave.ptm.exr"
"$ptm" preview --ptm "$out/weave.ptm.exr" -o "$out/preview.png"
# The first picture: the built-in drape wearing the weave (yarn colours from the maps' masks,
# their normal map, sheen), under one light: with K | without K | close-up with K.
"$ptm" preview --ptm "$out/weave.ptm.exr" --maps "$out/samples.maps.exr" --mesh drape \
    --repeat 10 --yarn-color warp=0.45,0.06,0.05 --yarn-color weft=0.75,0.6,0.35 --sheet \
    -o "$out/garment.png"

echo
echo "samples (K per light):  $out/samples.exr"
echo "light dome (.lp):       $out/samples.lp"
echo "occlusion PTM (ptm6, logistic): $out/weave.ptm.exr"
echo "GPU preview:            $out/preview.png"
echo "companion maps:         $out/samples.maps.exr"
echo "on a garment (with K | without K | close-up): $out/garment.png"
