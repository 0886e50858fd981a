#!/usr/bin/env bash
# Client test that needs Blender: PyPI `bpy` 5.0.1 (Blender as a Python module, for Python 3.11,
# ~1 GB installed) into the ignored folder .deps/bpy on first use, then a headless Cycles CPU
# render of a plane emitting K through the OSL script node and through the Blender-node group,
# compared with Ptm::eval at every pixel centre (ptm6 and ptm11, both links, both (u, v) maps),
# the same through the OSL MaterialX's generator writes for ND_ptm_occlusion_float (pinned
# MaterialX of .deps/py, includes inlined; compiled by Cycles' OSL compiler), and the lit example
# picture; learned bases (learned11, learned6) through ptm_occlusion_learned.osl, the node group
# and ND_ptm_occlusion_learned_float's generated OSL. Run by scripts/test.sh when PTM_TEST_CLIENTS=1.
#   LIT_PNG=docs/blender_lit.png bash scripts/test-clients.sh   # also re-render the README picture
set -euo pipefail
cd "$(dirname "$0")/.."
say() { printf 'test-clients: %s\n' "$*" >&2; }
PY=${PYTHON:-python3}
if [ ! -e .deps/bpy/.installed-5.0.1 ]; then
    "$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), "bpy 5.0 needs Python 3.11"' \
        || { say "bpy 5.0.1 is built for Python 3.11 only; set PYTHON=python3.11"; exit 1; }
    say "installing bpy==5.0.1 into .deps/bpy (about 1 GB)"
    "$PY" -m venv .deps/bpy
    .deps/bpy/bin/pip install -q bpy==5.0.1
    touch .deps/bpy/.installed-5.0.1
fi
bash scripts/setup.sh  # .deps/py: the pinned MaterialX that generates the OSL
# The workspace's one feature set (as scripts/test.sh builds): a `-p` build would resolve its own
# and compile the shared dependencies again.
cargo build --release -q --workspace --features "${PTM_CARGO_FEATURES:-ptm-runtime/window}" \
    --bin ptm --example ptm_eval
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
.deps/py/bin/python integrations/materialx/mtlx_osl.py "$work/ptm_k.osl" >/dev/null
.deps/py/bin/python integrations/materialx/mtlx_osl.py "$work/ptm_k_noflip.osl" --no-flip >/dev/null
.deps/py/bin/python integrations/materialx/mtlx_osl.py "$work/ptm_k_learned.osl" --learned >/dev/null
.deps/bpy/bin/python integrations/blender/test_blender.py target/release/ptm \
    target/release/examples/ptm_eval "$work/ptm_k.osl" "$work" ${LIT_PNG:+"$LIT_PNG"} 2>&1 \
    | grep -E '^(blender|Traceback|  File|[A-Za-z]*Error)' || { say "Blender test failed"; exit 1; }
