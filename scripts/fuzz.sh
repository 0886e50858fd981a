#!/usr/bin/env bash
# Mutation fuzzing of every reader (OBJ, .lp, WIF, sample-stack EXR, PTM EXR, caster PNG) on
# stable Rust: `scripts/fuzz.sh N [SEED]` runs N mutants per reader (default 10000, seed 1).
# Findings (panics, aborts, hangs, memory above the bound) are saved under fuzz/findings/ and
# fail the run; each must become a regression input in fuzz/corpus/<reader>/ or a unit test.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q -p ptm-fuzz
target="${CARGO_TARGET_DIR:-target}"
exec "$target/debug/ptm-fuzz" --cases "${1:-10000}" --seed "${2:-1}"
