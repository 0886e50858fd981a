#!/usr/bin/env bash
# A fixed set of outputs of every command, for showing that a change leaves them byte for byte
# as they were: bakes (stack, streaming identity and logistic fits, point lights, an OBJ),
# fits (both bases, links and maps, hold-out, half, renderer layout, HP export, an RTI image
# stack), conversions, farm parts and merges, previews (plane, caster under every blur method,
# perspective, turntable), swatches and the report's deterministic tables.
#
#   bash scripts/outputs.sh PTM OUT      # PTM: the ptm binary; OUT: an empty or new folder
#   diff OUT-before/SHA256SUMS OUT-after/SHA256SUMS
#
# OUT/SHA256SUMS lists every file written except those that record run time; OUT/json/ holds
# each command's `--json` object with its timing values removed (`seconds*`, `*_per_s`, load
# averages) and keys sorted, so `diff -r OUT-before/json OUT-after/json` shows a changed key or
# value. Each command is also listed in OUT/commands.txt.
set -euo pipefail
ptm=$(realpath "$1")
out=$2
mkdir -p "$out/json"
out=$(realpath "$out")
cd "$out"
: >commands.txt

# run NAME ARGS…: `ptm ARGS… --json`, its JSON with timings stripped into json/NAME.json.
run() {
    local name=$1
    shift
    echo "ptm $*" >>commands.txt
    "$ptm" "$@" --json >"json/$name.raw" 2>>stderr.txt
    python3 - "json/$name.raw" "json/$name.json" <<'PY'
import json, sys
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in sorted(v.items())
                if not (k.startswith("seconds") or k.endswith("_per_s") or k.startswith("load")
                        or k in ("threads", "kernel", "adapter", "gpu_ms", "ms"))}
    if isinstance(v, list):
        return [strip(x) for x in v]
    return v
with open(sys.argv[1]) as f:
    v = json.load(f)
with open(sys.argv[2], "w") as f:
    json.dump(strip(v), f, indent=1, sort_keys=True)
    f.write("\n")
PY
    rm "json/$name.raw"
}

# A caster image: an opaque disc and a bar on transparency (RGBA PNG, stdlib only).
python3 - caster.png <<'PY'
import struct, sys, zlib
w = h = 64
rows = []
for y in range(h):
    row = bytearray([0])
    for x in range(w):
        disc = (x - 20) ** 2 + (y - 24) ** 2 < 14 ** 2
        bar = 38 <= x < 56 and 10 <= y < 54
        a = 255 if disc else (160 if bar else 0)
        row += bytes([200, 80 if bar else 200, 40, a])
    rows.append(bytes(row))
def chunk(t, d):
    return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
png += chunk(b"IDAT", zlib.compress(b"".join(rows), 9)) + chunk(b"IEND", b"")
open(sys.argv[1], "wb").write(png)
PY

# Swatches.
run swatch-twill swatch 'twill?n=3&m=1' -o twill.obj
run swatch-jersey swatch jersey -o jersey.obj

# Bakes.
run bake-weave bake --swatch builtin:plain-weave --res 48 --dirs 24 --spp 4 -o weave.exr
run bake-twill-obj bake --swatch twill.obj --res 32,24 --dome rings:20x8,50x6 --spp 2 -o twill.exr
run bake-point bake --swatch builtin:plain-weave --res 24 --dirs 12 --light-distance 3 -o point.exr
run bake-fit6 bake --swatch builtin:jersey --res 32 --dirs 24 --spp 3 --fit ptm6 -o jersey6.ptm.exr
run bake-fit11-id bake --swatch builtin:velvet --res 32 --dirs 32 --fit ptm11 --link identity --uv projected -o velvet11.ptm.exr
run bake-fit-rgba bake --swatch builtin:plain-weave --res 32 --dirs 24 --fit ptm11 --layout rgba -o weave-rgba.ptm.exr

# Fits of the stored stack.
run fit6 fit weave.exr --basis ptm6 -o weave6.ptm.exr
run fit11-holdout fit weave.exr --basis ptm11 --holdout 4 -o weave11.ptm.exr
run fit6-patent fit weave.exr --basis ptm6 --link identity --uv projected --no-mips --export-hp weave6.ptm -o weave6-patent.ptm.exr
run fit11-half fit weave.exr --basis ptm11 --link identity --half -o weave11-half.ptm.exr
run fit6-rgba fit twill.exr --basis ptm6 --layout rgba -o twill6.ptm.exr
run fit-point fit point.exr --basis ptm6 --link identity -o point.ptm.exr
run convert convert twill6.ptm.c0.exr -o twill6-channels.ptm.exr

# An RTI image stack: previews of the patent PTM under six lights, with their .lp.
mkdir -p rti
"$ptm" preview --ptm weave6-patent.ptm.exr --size 48,48 --repeat 1 --light 2,1,3 -o rti/a.png 2>>stderr.txt
"$ptm" preview --ptm weave6-patent.ptm.exr --size 48,48 --repeat 1 --light -1,2,2 -o rti/b.png 2>>stderr.txt
"$ptm" preview --ptm weave6-patent.ptm.exr --size 48,48 --repeat 1 --light 0,-2,1 -o rti/c.png 2>>stderr.txt
"$ptm" preview --ptm weave6-patent.ptm.exr --size 48,48 --repeat 1 --light 1,1,4 -o rti/d.png 2>>stderr.txt
"$ptm" preview --ptm weave6-patent.ptm.exr --size 48,48 --repeat 1 --light -2,-1,2 -o rti/e.png 2>>stderr.txt
"$ptm" preview --ptm weave6-patent.ptm.exr --size 48,48 --repeat 1 --light 2,-2,3 -o rti/f.png 2>>stderr.txt
printf '6\na.png 2 1 3\nb.png -1 2 2\nc.png 0 -2 1\nd.png 1 1 4\ne.png -2 -1 2\nf.png 2 -2 3\n' >rti/lights.lp
run fit-images fit --images 'rti/*.png' --lights rti/lights.lp --basis ptm6 --link identity -o rti.ptm.exr

# Farm: shards of a stack and of a logistic fit, merged.
mkdir -p farm
for i in 0 1 2; do
    run "shard-stack-$i" bake --swatch builtin:plain-weave --res 48 --dirs 24 --spp 4 -o farm/weave.exr --shard "$i/3"
    run "shard-fit-$i" bake --swatch builtin:jersey --res 32 --dirs 24 --spp 3 --fit ptm6 -o farm/jersey6.ptm.exr --shard "$i/2" 2>/dev/null || true
done
run merge-stack merge farm/weave.part-*.exr -o weave-merged.exr
run merge-fit merge farm/jersey6.ptm.part-*.exr -o jersey6-merged.ptm.exr

# Previews.
run preview-plain preview --ptm weave6.ptm.exr --size 96,96 -o preview-plain.png --exr preview-plain.exr
for blur in sat mip separable explicit; do
    run "preview-$blur" preview --ptm weave11.ptm.exr --size 96,80 --caster caster.png --caster-height 0.4 --blur "$blur" -o "preview-$blur.png"
done
run preview-tilt preview --ptm jersey6.ptm.exr --size 80,80 --caster caster.png --caster-tilt 25 --colored-shadow -o preview-tilt.png
run preview-persp preview --ptm velvet11.ptm.exr --size 96,64 --camera -1,-1,1.2 --fov 50 -o preview-persp.png
run preview-turntable preview --ptm weave6.ptm.exr --size 48,48 --turntable 4 -o preview-turntable.png
run preview-nopTm preview --size 48,48 --caster caster.png -o preview-noptm.png

# The report's study (--quick): its CSVs without the columns that record or depend on run time
# (seconds, ms, time budgets, the Pareto front over time); the PNG of error against time and
# report.md, which quote times, are left out.
run report report --quick -o report
mkdir -p report-stripped
python3 - report report-stripped <<'PY'
import csv, os, re, sys
src, dst = sys.argv[1:3]
timed = re.compile(r"( s$| s |seconds|\bms\b|time|budget|pareto|best setting)", re.I)
for name in sorted(os.listdir(src)):
    if not name.endswith(".csv") or name == "recommendations.csv":  # chosen by time budget
        continue
    with open(os.path.join(src, name), newline="") as f:
        rows = list(csv.reader(f))
    keep = [i for i, h in enumerate(rows[0]) if not timed.search(h)]
    with open(os.path.join(dst, name), "w", newline="") as f:
        csv.writer(f).writerows([[r[i] for i in keep] for r in rows])
PY

# Everything but what records run time (report CSVs with timing columns, stderr).
find . -type f ! -name SHA256SUMS ! -name stderr.txt ! -path './json/*' ! -name commands.txt \
    ! -path './report/*.csv' ! -name error_vs_time.png ! -name report.md -print0 \
    | sort -z | xargs -0 sha256sum >SHA256SUMS
echo "outputs: $(wc -l <SHA256SUMS) files hashed in $out/SHA256SUMS, $(ls json | wc -l) JSON objects in $out/json" >&2
