#!/usr/bin/env bash
# Idempotent fresh-machine setup for ptm: system packages (libclang for bindgen, lavapipe
# software Vulkan for wgpu, Xvfb and the X11 libraries winit opens for the preview window's
# tests) and Embree 4.4 from the pinned PyPI wheel `embreex`, unpacked into
# the ignored folder `.deps/embree`. Safe to run any number of times; quiet when nothing to do.
set -euo pipefail
cd "$(dirname "$0")/.."

say() { printf 'setup: %s\n' "$*" >&2; }

# --- system packages -------------------------------------------------------------------------
need_pkgs=()
# xvfb + xauth: a virtual X server and xvfb-run (which needs xauth, only recommended by xvfb).
# winit dlopens libX11, libX11-xcb, libXcursor, libXi and libxkbcommon-x11 at run time.
# python3-venv/pip: the pinned client venv (.deps/py); glslang-tools: MaterialX's GLSL compiled.
for p in libclang-dev mesa-vulkan-drivers libvulkan1 fonts-dejavu-core \
    xvfb xauth libx11-6 libx11-xcb1 libxcursor1 libxi6 libxkbcommon-x11-0 \
    python3-venv python3-pip glslang-tools; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || need_pkgs+=("$p")
done
if ((${#need_pkgs[@]})); then
    if [ "$(id -u)" -eq 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else
        say "missing Debian packages: ${need_pkgs[*]}; run as root or install them: apt-get install -y ${need_pkgs[*]}"
        exit 1
    fi
    say "installing ${need_pkgs[*]}"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq >/dev/null
    $SUDO apt-get install -y -qq --no-install-recommends "${need_pkgs[@]}" >/dev/null
fi

# --- Mesa 25 (lavapipe with ray queries) from bookworm-backports ------------------------------
# The GPU bake (`ptm bake --device gpu`, crate gpubake/) needs Vulkan ray queries
# (VK_KHR_ray_query); Debian 12's Mesa 22.3 lavapipe has none, the Mesa 25 of bookworm-backports
# has them. It replaces 22.3 for everything (the runtime's goldens and twins pass on it; see
# gpubake/ in ARCHITECTURE.md for why not beside it). Backports have priority 100, so nothing
# else is upgraded from them. Other distributions: install a Mesa >= 25 yourself.
mesa_major() { v=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true); v=${v#*:}; echo "${v%%.*}"; }
codename=$(. /etc/os-release 2>/dev/null && echo "${VERSION_CODENAME:-}" || true)
if [ "$codename" = bookworm ] && [ "$(mesa_major)" != "" ] && [ "$(mesa_major)" -lt 25 ]; then
    if [ "$(id -u)" -eq 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else
        say "Mesa $(mesa_major) has no Vulkan ray queries; run as root or install Mesa 25 from bookworm-backports: apt-get install -t bookworm-backports mesa-vulkan-drivers"
        exit 1
    fi
    bpo=/etc/apt/sources.list.d/ptm-bookworm-backports.sources
    if ! grep -rqs "bookworm-backports" /etc/apt/sources.list /etc/apt/sources.list.d/; then
        # The machine's own bookworm mirror and keyring (deb822 or one-line sources).
        uri=$(awk '/^URIs:/ {u=$2} /^Suites:/ && / bookworm( |$)/ && u {print u; exit}' /etc/apt/sources.list.d/*.sources 2>/dev/null || true)
        key=$(awk '/^URIs:/ {u=$2} /^Signed-By:/ {k=$2} /^Suites:/ && / bookworm( |$)/ {s=1} s && k && u {print k; exit}' /etc/apt/sources.list.d/*.sources 2>/dev/null || true)
        [ -n "$uri" ] || uri=$(awk '$1 == "deb" { for (i = 2; i < NF; i++) if ($i ~ /^[a-z+]+:\/\//) { if ($(i + 1) == "bookworm") { print $i; exit } break } }' /etc/apt/sources.list 2>/dev/null || true)
        uri=${uri:-http://deb.debian.org/debian}
        key=${key:-/usr/share/keyrings/debian-archive-keyring.gpg}
        say "adding bookworm-backports ($uri) for Mesa 25"
        printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: %s\n' "$uri" "$key" |
            $SUDO tee "$bpo" >/dev/null
    fi
    say "installing Mesa 25 (mesa-vulkan-drivers) from bookworm-backports: lavapipe with ray queries"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq >/dev/null
    $SUDO apt-get install -y -qq --no-install-recommends -t bookworm-backports mesa-vulkan-drivers >/dev/null
    [ "$(mesa_major)" -ge 25 ] || { say "Mesa from bookworm-backports did not install (have $(mesa_major))"; exit 1; }
fi

# --- Embree 4 ----------------------------------------------------------------------------------
# EMBREE_DIR=/path/to/embree4 (with lib/libembree4.so) skips the wheel entirely.
if [ -n "${EMBREE_DIR:-}" ]; then
    ls "$EMBREE_DIR"/lib*/libembree4.so* >/dev/null 2>&1 || { say "EMBREE_DIR=$EMBREE_DIR has no lib/libembree4.so*"; exit 1; }
else
    dest=.deps/embree
    if [ ! -e "$dest/lib/libembree4.so" ]; then
        say "fetching Embree 4.4 from the PyPI wheel embreex==4.4.0.post1"
        tmp=$(mktemp -d)
        trap 'rm -rf "$tmp"' EXIT
        PY=${PYTHON:-python3}
        command -v "$PY" >/dev/null || { say "python3 with pip is needed to fetch Embree (or set EMBREE_DIR)"; exit 1; }
        "$PY" -m pip download -q --no-deps --only-binary=:all: --platform manylinux_2_28_x86_64 \
            --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
            --python-version 3.11 -d "$tmp" embreex==4.4.0.post1
        "$PY" - "$tmp" <<'PYEOF'
import sys, zipfile, glob, os
tmp = sys.argv[1]
whl = glob.glob(os.path.join(tmp, "*.whl"))[0]
with zipfile.ZipFile(whl) as z:
    for n in z.namelist():
        if n.startswith("embreex.libs/"):
            z.extract(n, tmp)
PYEOF
        rm -rf "$dest.tmp" && mkdir -p "$dest.tmp/lib"
        cp "$tmp"/embreex.libs/* "$dest.tmp/lib/"
        emb=$(cd "$dest.tmp/lib" && ls libembree4-*.so.4 | head -1)
        # The wheel's soname is mangled (libembree4-<hash>.so.4); the linker needs libembree4.so.
        ln -sf "$emb" "$dest.tmp/lib/libembree4.so"
        rm -rf "$dest" && mv "$dest.tmp" "$dest"
        say "Embree 4.4 in $dest/lib"
    fi
fi

# --- Python tooling of the test suite (MaterialX, OpenEXR, OpenImageIO) -----------------------
# One ignored venv, pinned versions; reinstalled only when scripts/requirements-clients.txt changes.
venv=.deps/py
req=scripts/requirements-clients.txt
stamp="$venv/.installed-$(sha256sum "$req" | cut -c1-16)"
if [ ! -e "$stamp" ]; then
    say "installing $(grep -v '^#' "$req" | tr '\n' ' ')into $venv"
    "${PYTHON:-python3}" -m venv "$venv"
    "$venv/bin/pip" install -q --disable-pip-version-check -r "$req"
    rm -f "$venv"/.installed-*
    touch "$stamp"
fi

# --- A second CPython for the Python module's abi3 wheel ---------------------------------------
# scripts/test.sh builds the module once as an abi3 wheel (cp39-abi3: CPython >= 3.9) and tests
# it on .deps/py (CPython 3.11) and on .deps/py2, a venv of the lowest version the wheel
# supports: $PTM_PYTHON2 if set, else python3.9 on PATH or pyenv's 3.9, else CPython 3.9 fetched
# by PyPI's `uv` (`uv python install`, a python-build-standalone download). Only numpy and
# OpenEXR, the test's imports, pinned to the last releases for 3.9.
venv2=.deps/py2
pins2="numpy==2.0.2 OpenEXR==3.4.17"
stamp2="$venv2/.installed-$(echo "$pins2" | sha256sum | cut -c1-16)"
if [ ! -e "$stamp2" ]; then
    # The first candidate that runs as CPython 3.9 (a pyenv shim on PATH fails unless selected).
    py2=""
    for c in ${PTM_PYTHON2:-} "$(command -v python3.9 || true)" \
        $(ls -d "$(pyenv root 2>/dev/null || echo /nonexistent)"/versions/3.9.*/bin/python3.9 \
            "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.9.*/bin/python3.9 2>/dev/null); do
        if [ -n "$c" ] && "$c" -c 'import sys; assert sys.version_info[:2] == (3, 9)' 2>/dev/null; then
            py2=$c
            break
        fi
    done
    if [ -z "$py2" ]; then
        say "fetching CPython 3.9 with uv into .deps/uv-python"
        if .deps/py/bin/pip install -q --disable-pip-version-check uv==0.13.8 &&
            UV_PYTHON_INSTALL_DIR=.deps/uv-python .deps/py/bin/uv python install -q 3.9; then
            py2=$(UV_PYTHON_INSTALL_DIR=.deps/uv-python .deps/py/bin/uv python find 3.9)
        fi
    fi
    if [ -n "$py2" ]; then
        say "installing $pins2 into $venv2 ($("$py2" -c 'import platform; print("CPython", platform.python_version())'))"
        rm -rf "$venv2"
        "$py2" -m venv "$venv2"
        # shellcheck disable=SC2086
        "$venv2/bin/pip" install -q --disable-pip-version-check $pins2
        touch "$stamp2"
    else
        # No 3.9 here and none to fetch: scripts/test.sh then tests the wheel on 3.11 alone and
        # says so; set PTM_PYTHON2 to a CPython 3.9 to test both.
        say "WARNING: no CPython 3.9 found or fetched; the Python module is tested on one interpreter"
        rm -rf "$venv2"
    fi
fi
