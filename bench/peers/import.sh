#!/usr/bin/env bash
# bench/peers/import.sh -- rbss's imported models against MuJoCo and Pinocchio loading the same
# URDF / MJCF files (issue 21; see README.md, "import.sh").
#
#   bench/peers/import.sh        # needs target/release/rbss and rbss-codegen (cargo build --release)
#
# Steps: the venv of run.sh (venv.sh) with pin and mujoco (the Python bindings) -> for each test
# source of codegen/tests/import/: random states on its loops and rbss's M, psi and forward
# dynamics from `rbss eval --model-file` (the model compiled into the --model-file cache) ->
# MuJoCo and Pinocchio on the same source -> IMPORT.md.
# Environment: RBSS (the rbss binary), PYTHON (python3 >= 3.11 for the venv), IMPORT_STATES
# (states per model, default 20), IMPORT_PUBLIC (0: without the two public URDFs), RBSS_CACHE (default bench/peers/build/rbss-cache) and
# RBSS_CACHE_TARGET (default the workspace's target/, so that the runtime and its dependencies
# are not compiled into a second build directory).
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
RBSS=${RBSS:-$ROOT/target/release/rbss}
PYTHON=${PYTHON:-python3}
VENV=$HERE/.venv
BUILD=$HERE/build
export RBSS_CACHE=${RBSS_CACHE:-$BUILD/rbss-cache}
export RBSS_CACHE_TARGET=${RBSS_CACHE_TARGET:-$ROOT/target}

die() { echo "bench/peers: ERROR: $*" >&2; exit 1; }
step() { echo "==> $*" >&2; }
trap 'die "failed at line $LINENO: $BASH_COMMAND"' ERR

source "$HERE/venv.sh"
peers_venv "pin==$PIN_VERSION" "mujoco==$MUJOCO_VERSION"

# two public URDFs (example-robot-data's wheel, ~130 MB, kept in build/; IMPORT_PUBLIC=0 skips them)
ERD_VERSION=6.0.0
if [[ ${IMPORT_PUBLIC:-1} != 0 ]] && ! ls "$BUILD"/example_robot_data-$ERD_VERSION-*.whl >/dev/null 2>&1; then
  mkdir -p "$BUILD"
  step "pip download example-robot-data==$ERD_VERSION (PyPI, ~130 MB, not installed: two URDFs are read from it)"
  "$VENV/bin/python" -m pip download --quiet --disable-pip-version-check --no-deps \
    -d "$BUILD" "example-robot-data==$ERD_VERSION" || die "pip download example-robot-data failed"
fi

[[ -x $RBSS ]] || die "$RBSS not found: build it first (cargo build --release) or set RBSS=..."
mkdir -p "$BUILD"
step "imported models: rbss eval --model-file (the first run compiles each model, ~15 s each), MuJoCo, Pinocchio"
nice -n 10 "$VENV/bin/python" "$HERE/import_check.py" "$BUILD" "$RBSS" "$HERE/IMPORT.md" >"$BUILD/import.log" ||
  die "import_check.py failed (see above)"
echo "bench/peers: wrote $HERE/IMPORT.md" >&2
