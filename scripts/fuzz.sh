#!/usr/bin/env bash
# Mutation fuzzing of every reader (OBJ, .lp, WIF, sample-stack EXR, PTM EXR, renderer-layout
# parts, caster PNG) on stable Rust: `scripts/fuzz.sh N [SEED]` runs N mutants per reader (default 10000, seed 1).
# Findings (panics, aborts, hangs, memory above the bound) are saved under fuzz/findings/ and
# fail the run; each must become a regression input in fuzz/corpus/<reader>/ or a unit test.
set -euo pipefail
cd "$(dirname "$0")/.."
# PTM_CARGO_FEATURES (scripts/test.sh sets it): build with the workspace's feature set, so the
# dependencies the test build compiled are reused rather than compiled again for one package.
cargo build -q --workspace --bin ptm-fuzz ${PTM_CARGO_FEATURES:+--features "$PTM_CARGO_FEATURES"}
target="${CARGO_TARGET_DIR:-target}"
exec "$target/debug/ptm-fuzz" --cases "${1:-10000}" --seed "${2:-1}"
