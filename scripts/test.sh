#!/usr/bin/env bash
# The whole test suite from a fresh Debian machine with Rust: installs what the tests need
# (idempotent: a few checks and nothing else when everything is present), then runs them.
#
#   libclang-dev   openfx-sys generates the OpenFX bindings from the official headers (bindgen)
#   libopenexr-dev, pkg-config   OpenEXR's C++ library, which writes the deep EXR output
#                  (build.rs builds the deep writer only where pkg-config finds it)
#   blender        the reference for camera alignment (Debian's 3.4, run headless)
#   numpy, msgpack the independent NumPy references of the trained fields and splats
#   mpmath         the quadrature reference of the renderer's far share of a linear piece
#   OpenEXR        OpenEXR's own library (PyPI's bindings, ≥ 3.3 for deep files), reading
#                  back the EXR output, flat and deep
#   opencolorio    OpenColorIO's own built-in configuration, the reference of the output
#                  colour spaces
#   mmh3           MurmurHash3 for the Cryptomatte decoder written from the specification
#   python3-numpy  Blender's own Python (Debian's build uses the system's) for the add-on's
#                  splat import
#   bpy 4.5, 5.0   Blender as a Python module (PyPI's `bpy`, in two Python 3.11 virtual
#                  environments under ${NERFX_BPY_DIR:-~/.cache/nerfx-bpy}): the Blender tests
#                  run the add-on and Cycles in 3.4, 4.5 LTS and 5.0
#   mdbook         builds the user's guide in docs/ (tests/command_line/docs.rs checks its links)
#   slurm-wlm, munge   tests/farm.rs runs a one-node Slurm cluster (slurmctld, slurmd, munged;
#                  started and stopped by the test, as root)
#   openjd-cli     `openjd check` and `openjd run` of the Open Job Description templates
#   opencue-pyoutline  PyOutline loads and serialises the OpenCue scripts (no Cuebot);
#                  `packaging`, which its Cue back end imports without declaring it
#
# Nothing is skipped when a tool is missing: the tests that need one fail. Extra arguments go
# to `cargo test` (a test name, `-- --nocapture`).
set -euo pipefail
cd "$(dirname "$0")/.."

as_root() {
    if [ "$(id -u)" = 0 ]; then
        "$@"
    elif command -v sudo >/dev/null; then
        sudo "$@"
    else
        echo "scripts/test.sh: '$*' needs root (or sudo)" >&2
        return 1
    fi
}

apt_install() {
    export DEBIAN_FRONTEND=noninteractive
    as_root apt-get update -qq
    as_root apt-get install -y -qq "$@"
}

need_apt=()
command -v cc >/dev/null || need_apt+=(build-essential)
dpkg -s libclang-dev >/dev/null 2>&1 || need_apt+=(libclang-dev)
command -v pkg-config >/dev/null || need_apt+=(pkg-config)
dpkg -s libopenexr-dev >/dev/null 2>&1 || need_apt+=(libopenexr-dev)
command -v blender >/dev/null || need_apt+=(blender)
command -v python3 >/dev/null || need_apt+=(python3)
command -v slurmctld >/dev/null || need_apt+=(slurm-wlm)
command -v munged >/dev/null || need_apt+=(munge)
if ((${#need_apt[@]})); then
    echo "== installing ${need_apt[*]}"
    apt_install "${need_apt[@]}"
fi

# OpenEXR's bindings read deep files from 3.3 on.
if ! python3 -c "import numpy, msgpack, mpmath, OpenEXR, PyOpenColorIO, mmh3
assert tuple(map(int, OpenEXR.__version__.split('.')[:2])) >= (3, 3)" 2>/dev/null; then
    echo "== installing numpy, msgpack, mpmath, OpenEXR, opencolorio and mmh3 for $(command -v python3)"
    # A pip-managed Python (pyenv, a venv) takes them from PyPI; Debian's own python3 refuses
    # pip (externally managed) and takes its packages, and OpenEXR, which Debian does not
    # package for Python, from PyPI beside them.
    python3 -m pip install --quiet numpy msgpack mpmath 'OpenEXR>=3.3' opencolorio mmh3 2>/dev/null || {
        apt_install python3-numpy python3-msgpack python3-mpmath python3-pip
        PIP_BREAK_SYSTEM_PACKAGES=1 python3 -m pip install --quiet 'OpenEXR>=3.3' opencolorio mmh3
    }
    python3 -c "import numpy, msgpack, mpmath, OpenEXR, PyOpenColorIO, mmh3"
fi

# PyOutline's Cue back end imports `packaging` without declaring it.
if ! command -v openjd >/dev/null || ! python3 -c "import outline, packaging" 2>/dev/null; then
    echo "== installing openjd-cli, opencue-pyoutline and packaging for $(command -v python3)"
    python3 -m pip install --quiet openjd-cli opencue-pyoutline packaging 2>/dev/null ||
        PIP_BREAK_SYSTEM_PACKAGES=1 python3 -m pip install --quiet openjd-cli opencue-pyoutline \
            packaging
    command -v openjd >/dev/null && python3 -c "import outline, packaging"
fi

if ! blender -b --factory-startup --python-exit-code 1 --python-expr "import numpy" \
    >/dev/null 2>&1; then
    echo "== installing numpy for Blender's Python"
    apt_install python3-numpy
fi

# PyPI's bpy wheels are built for CPython 3.11 (4.5 and 5.0 alike); without a python3.11 on
# the machine, uv (from PyPI) fetches one.
bpy_dir="${NERFX_BPY_DIR:-$HOME/.cache/nerfx-bpy}"
for version in 4.5.15 5.0.1; do
    venv="$bpy_dir/bpy-${version%.*}"
    if ! "$venv/bin/python" -c "import bpy, numpy; assert bpy.app.version_string.startswith('${version%.*}')" \
        >/dev/null 2>&1; then
        echo "== installing bpy $version into $venv"
        python311="$(command -v python3.11 || true)"
        if [ -z "$python311" ]; then
            python3 -m pip install --quiet uv 2>/dev/null ||
                PIP_BREAK_SYSTEM_PACKAGES=1 python3 -m pip install --quiet uv
            python3 -m uv python install 3.11
            python311="$(python3 -m uv python find 3.11)"
        fi
        rm -rf "$venv"
        mkdir -p "$bpy_dir"
        "$python311" -m venv "$venv"
        "$venv/bin/python" -m pip install --quiet "bpy==$version" numpy
    fi
done

if ! command -v mdbook >/dev/null; then
    echo "== installing mdbook"
    cargo install --quiet --locked mdbook --no-default-features --features search
fi

echo "== cargo test --workspace --features cross-checks"
cargo test --workspace --features cross-checks "$@"

echo "== mdbook build docs"
mdbook build docs
