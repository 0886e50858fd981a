#!/usr/bin/env bash
# Regenerates docs/examples/capture/: a small stand-in for a photographed RTI capture, eight
# 48×48 8-bit PNGs of a baked twill under eight lights (visibility 1 − K times the light's
# irradiance, as `ptm preview` renders one tile) and lights.lp naming each image's light
# direction, for the README's `ptm fit --images` recipe.
#   bash docs/examples/make-capture.sh [PTM_BIN]
set -euo pipefail
ptm=${1:-ptm}
out="$(cd "$(dirname "$0")" && pwd)/capture"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$ptm" swatch 'twill?n=3&m=1' -o "$work/twill.obj" 2>/dev/null
"$ptm" bake --swatch "$work/twill.obj" --res 48 --dirs 64 --spp 4 --fit ptm11 \
    -o "$work/twill.ptm.exr" 2>/dev/null
rm -rf "$out"
mkdir -p "$out"
# Directions (x y z, unit length) at 25°–70° elevation around the dome.
dirs=("0.77 0.32 0.55" "-0.32 0.77 0.55" "-0.77 -0.32 0.55" "0.32 -0.77 0.55"
      "0.58 -0.58 0.57" "0.30 0.30 0.91" "-0.85 0.35 0.40" "0.35 0.85 0.40")
printf '%s\n' "${#dirs[@]}" >"$out/lights.lp"
i=0
for d in "${dirs[@]}"; do
    read -r x y z <<<"$d"
    name=$(printf 'light%02d.png' "$i")
    # Far (100 tile widths) and small: a distant light as the .lp says.
    "$ptm" preview --ptm "$work/twill.ptm.exr" --repeat 1 --size 48,48 --albedo 1,1,1 \
        --light "$(python3 -c "print(','.join(str(100 * c) for c in ($x, $y, $z)))")" \
        --light-radius 0.01 -o "$out/$name" 2>/dev/null
    printf '%s %s %s %s\n' "$name" "$x" "$y" "$z" >>"$out/lights.lp"
    i=$((i + 1))
done
echo "wrote $out ($i images and lights.lp)"
