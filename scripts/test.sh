#!/usr/bin/env bash
# The whole test suite on a fresh machine: setup (idempotent), formatting and lint gates, the
# dependency-boundary check, then every test of the workspace (GPU tests on lavapipe).
set -euo pipefail
cd "$(dirname "$0")/.."

# Each step says how long it took, and the end lists them all: where a slow CI run spent its time.
t_step=$SECONDS
step_name=""
step_times=""
step() {
    if [ -n "$step_name" ]; then
        step_times+="$(printf '%6d s  %s' $((SECONDS - t_step)) "$step_name")"$'\n'
    fi
    step_name=$1
    t_step=$SECONDS
    echo "== $1" >&2
}
summary() {
    local rc=$?
    step_times+="$(printf '%6d s  %s' $((SECONDS - t_step)) "$step_name")"$'\n'
    echo "== time per step (rc $rc, $SECONDS s in all)" >&2
    printf '%s' "$step_times" >&2
}
trap summary EXIT

step "setup (scripts/setup.sh)"
bash scripts/setup.sh
export CARGO_TERM_COLOR=${CARGO_TERM_COLOR:-never}
# Mesa's implicit Vulkan layer VK_LAYER_MESA_device_select probes Wayland; without a session
# libwayland prints an error per GPU test. Nothing to select headless (the ptm binary does the same).
export NODEVICE_SELECT=${NODEVICE_SELECT:-1}

step "cargo fmt --check"
cargo fmt --all -- --check

step "ptm-fit depends on neither Embree nor wgpu"
if cargo tree -p ptm-fit -e normal --prefix none | grep -E '^(embree4-sys|wgpu|wgpu-core|wgpu-hal|naga) ' ; then
    echo "ptm-fit must not depend on Embree or wgpu (see ARCHITECTURE.md)" >&2
    exit 1
fi

step "ptm-format (what a render pipeline takes) depends on no solver, thread pool, image codec, Embree or wgpu"
if cargo tree -p ptm-format -e normal --prefix none | grep -E '^(nalgebra|rayon|rayon-core|image|glob|embree4-sys|wgpu|wgpu-core|wgpu-hal|naga) ' ; then
    echo "ptm-format must depend on none of nalgebra, rayon, image, glob, embree4-sys, wgpu, naga (see ARCHITECTURE.md)" >&2
    exit 1
fi

step "ptm-python (the Python module) takes ptm-format, not the fitter"
if cargo tree -p ptm-python -e normal --prefix none | grep -E '^(ptm-fit|nalgebra|rayon|rayon-core|image|glob|embree4-sys|wgpu) ' ; then
    echo "ptm-python must depend on ptm-format, not on ptm-fit, nalgebra, rayon, image, glob, embree4-sys or wgpu (see ARCHITECTURE.md)" >&2
    exit 1
fi

step "ptm-bake (the CPU bake) links no wgpu: the GPU bake is ptm-gpubake's"
if cargo tree -p ptm-bake -e normal --prefix none | grep -E '^(wgpu|wgpu-core|wgpu-hal|naga|ptm-gpubake) ' ; then
    echo "ptm-bake must not depend on wgpu or ptm-gpubake: the GPU bake lives in gpubake/ (see ARCHITECTURE.md)" >&2
    exit 1
fi

step "ptm-bake, ptm-gpubake and ptm-runtime take the file layer (ptm-format), not the fitter"
for c in ptm-bake ptm-gpubake ptm-runtime; do
    if cargo tree -p "$c" -e normal --prefix none | grep -E '^ptm-fit ' ; then
        echo "$c must not depend on ptm-fit: it never fits; take ptm-format (see ARCHITECTURE.md)" >&2
        exit 1
    fi
done

step "no import cycle between the files of any crate, no fit/src file over 700 lines"
python3 scripts/check-structure.py

step "cargo clippy --all-targets"
cargo clippy --workspace --all-targets -- -D warnings

step "cargo clippy --features ptm/window (the preview window compiles; it runs only with a display)"
cargo clippy --workspace --features ptm/window --all-targets -- -D warnings

step "cargo doc -D warnings, the window module too (every intra-doc link resolves)"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --features ptm-runtime/window --no-deps

# Every build below selects the whole workspace with the same features, so cargo resolves one
# feature set and compiles each dependency once (a `-p CRATE` build resolves its own set and
# compiles the shared dependencies again: that cost a fresh machine about 10 minutes). The
# runtime's window module is in that set, so its tests run with the others.
export PTM_CARGO_FEATURES=ptm-runtime/window
ws=(--workspace --features "$PTM_CARGO_FEATURES")

step "the --json key snapshots (tests/snapshots/json_keys.txt, docs/json.md; UPDATE_SNAPSHOTS=1 rewrites)"
cargo test "${ws[@]}" --bin ptm json::

# The preview window's tests need a display: a virtual X server (Xvfb, installed by setup.sh)
# with lavapipe presenting to it. PTM_REQUIRE_DISPLAY=1 turns their "SKIPPED <name>" (no
# display) into a failure, so they cannot pass here without running. -noreset: an X server
# resets when its last client leaves, and a client that connects during the reset fails; two
# window tests (one in a child process) connect and leave at their own times, and one run
# failed so ("could not connect to the X server") where the rerun passed.
step "cargo test (the preview window's tests under Xvfb)"
PTM_REQUIRE_DISPLAY=1 xvfb-run -a -s "-screen 0 1024x768x24 -noreset" cargo test "${ws[@]}"

step "mutation fuzzing of the readers, 2000 mutants each (scripts/fuzz.sh N for more)"
bash scripts/fuzz.sh 2000

step "every file we write opened by Python OpenEXR and OpenImageIO, compared with our reader (tests/clients)"
rd_work=$(mktemp -d)
.deps/py/bin/python tests/clients/test_readers.py "$PWD/target/debug/ptm" "$PWD/target/debug/examples/ptm_eval" "$rd_work"
rm -rf "$rd_work"

step "PTMs rewritten by oiiotool, maketx and Python OpenEXR keep loading, with their K (tests/clients)"
rw_work=$(mktemp -d)
.deps/py/bin/python tests/clients/test_rewritten.py "$PWD/target/debug/ptm" "$PWD/target/debug/examples/ptm_eval" "$rw_work" \
    | grep -v '^rewritten: ok'
rm -rf "$rw_work"

step "the OSL shader group of docs/pipeline.md against the OSL shaders it names (integrations/osl)"
.deps/py/bin/python integrations/osl/test_readme_example.py

step "the Python module ptm (python/, maturin): one abi3 wheel on two interpreters, against Ptm::eval, round trips, errors, the docs/pipeline.md example (tests/clients)"
# A release build: the test times eval and a pipeline gets this build; it adds about 1 min.
# One abi3 wheel (cp39-abi3: CPython >= 3.9), installed into the venv's CPython 3.11 and into
# .deps/py2, the second interpreter scripts/setup.sh provides, and tested on both.
t_module=$SECONDS
rm -rf target/wheels/ptm
.deps/py/bin/maturin build --release -q -m python/Cargo.toml -i .deps/py/bin/python -o target/wheels/ptm
wheel=$(ls target/wheels/ptm/ptm-*.whl)
case "$wheel" in
    *-cp39-abi3-*) ;;
    *) echo "the Python module's wheel $wheel is not abi3 for CPython >= 3.9 (cp39-abi3)" >&2; exit 1 ;;
esac
pythons=(.deps/py)
if [ -x .deps/py2/bin/python ]; then
    pythons+=(.deps/py2)
else
    echo "WARNING: no .deps/py2 (scripts/setup.sh found no CPython 3.9): the wheel is tested on one interpreter" >&2
fi
for py in "${pythons[@]}"; do
    "$py/bin/pip" install -q --disable-pip-version-check --force-reinstall --no-deps "$wheel"
done
echo "python module: built and installed in $((SECONDS - t_module)) s" >&2
for py in "${pythons[@]}"; do
    py_work=$(mktemp -d)
    echo "python module on $("$py/bin/python" -c 'import platform; print("CPython", platform.python_version())')" >&2
    "$py/bin/python" tests/clients/test_python_module.py "$PWD/target/debug/ptm" "$PWD/target/debug/examples/ptm_eval" "$py_work"
    rm -rf "$py_work"
done

step "MaterialX nodedef: validate, generate OSL and GLSL, compile the GLSL; its K in numpy against Ptm::eval (integrations/materialx)"
mx_work=$(mktemp -d)
.deps/py/bin/python integrations/materialx/test_materialx.py "$PWD/target/debug/ptm" "$PWD/target/debug/examples/ptm_eval" "$mx_work"
rm -rf "$mx_work"

if [ "${PTM_TEST_CLIENTS:-0}" = 1 ]; then
    step "Blender (PyPI bpy, Cycles CPU): OSL and node-group K against Ptm::eval (scripts/test-clients.sh)"
    bash scripts/test-clients.sh
fi

step "farm bake on a real single-node Slurm (scripts/test-slurm.sh)"
bash scripts/test-slurm.sh
