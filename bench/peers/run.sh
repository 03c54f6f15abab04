#!/usr/bin/env bash
# bench/peers/run.sh -- rbss beside Pinocchio and MuJoCo on the paper's 6-UPS (see README.md).
#
#   bench/peers/run.sh            # from anywhere; needs target/release/rbss (cargo build --release)
#
# Steps: venv with pin / mujoco-core / cmeel-eigen from PyPI (reused when present) -> C++ harness
# (rebuilt when harness.cpp changes) -> states and rbss's numbers from the rbss CLI -> harness:
# agreement checks and timing -> `rbss bench solvers` right after -> RESULT.md, peers.csv.
# Environment: RBSS (the rbss binary), PYTHON (the interpreter for the venv, python3 >= 3.11).
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
RBSS=${RBSS:-$ROOT/target/release/rbss}
PYTHON=${PYTHON:-python3}
VENV=$HERE/.venv
BUILD=$HERE/build
PIN_VERSION=4.1.0
MUJOCO_VERSION=4.0.0     # the `mujoco` 4.0.0 wheel is pure Python; `mujoco-core` ships libmujoco + headers
EIGEN_VERSION=3.4.1

die() { echo "bench/peers: ERROR: $*" >&2; exit 1; }
step() { echo "==> $*" >&2; }
trap 'die "failed at line $LINENO: $BASH_COMMAND"' ERR

# ---- 1. the venv (idempotent) ------------------------------------------------------------------
step "venv $VENV"
if [[ ! -x $VENV/bin/python ]]; then
  command -v "$PYTHON" >/dev/null || die "$PYTHON not found (set PYTHON=python3.11 or newer)"
  "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' ||
    die "$PYTHON is older than 3.11 (mujoco-core $MUJOCO_VERSION needs >= 3.11)"
  "$PYTHON" -m venv "$VENV" || die "could not create the venv (python3-venv missing?)"
fi
want="pin==$PIN_VERSION mujoco-core==$MUJOCO_VERSION cmeel-eigen==$EIGEN_VERSION"
have=$("$VENV/bin/python" -m pip freeze 2>/dev/null || true)
missing=0
for p in $want; do grep -qix "$p" <<<"$have" || missing=1; done
if [[ $missing == 1 ]]; then
  step "pip install $want (PyPI, ~150 MB)"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check $want ||
    die "pip install failed: is PyPI reachable? ($want)"
fi
SITE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
CMEEL=$SITE/cmeel.prefix
MJ=$SITE/mujoco
MJLIB=$(ls "$MJ"/libmujoco.so.* 2>/dev/null | head -n1 || true)
[[ -f $CMEEL/include/pinocchio/algorithm/constrained-dynamics.hpp ]] || die "Pinocchio headers missing in $CMEEL"
[[ -f $CMEEL/lib/libpinocchio_default.so ]] || die "libpinocchio_default.so missing in $CMEEL/lib"
[[ -f $CMEEL/include/eigen3/Eigen/Dense ]] || die "Eigen headers missing in $CMEEL/include/eigen3"
[[ -n $MJLIB && -f $MJ/include/mujoco/mujoco.h ]] ||
  die "libmujoco.so.* or mujoco/mujoco.h missing in $MJ (does the mujoco-core wheel still ship them?)"

# ---- 2. the harness (rebuilt when the source or the flags change) ------------------------------
mkdir -p "$BUILD"
CXXFLAGS=(-std=c++17 -O3 -DNDEBUG -Wno-deprecated-declarations
  -DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION -DBOOST_MPL_LIMIT_LIST_SIZE=30
  -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS
  -DBOOST_FUSION_INVOKE_MAX_ARITY=12
  -I"$CMEEL/include" -I"$CMEEL/include/eigen3" -I"$MJ/include")
LDFLAGS=(-L"$CMEEL/lib" -lpinocchio_default "$MJLIB" -Wl,-rpath,"$CMEEL/lib" -Wl,-rpath,"$MJ")
command -v g++ >/dev/null || die "g++ not found"
stamp="$(g++ --version | head -n1) ${CXXFLAGS[*]} ${LDFLAGS[*]} $(sha256sum "$HERE/harness.cpp" | cut -d' ' -f1)"
if [[ ! -x $BUILD/harness || ! -f $BUILD/harness.stamp || $(cat "$BUILD/harness.stamp") != "$stamp" ]]; then
  step "g++ harness.cpp (Pinocchio is header-heavy: 1 to 2 minutes)"
  g++ "${CXXFLAGS[@]}" "$HERE/harness.cpp" -o "$BUILD/harness" "${LDFLAGS[@]}" ||
    die "compiling harness.cpp failed"
  echo "$stamp" >"$BUILD/harness.stamp"
fi

# ---- 3. rbss's numbers --------------------------------------------------------------------------
[[ -x $RBSS ]] || die "$RBSS not found: build it first (cargo build --release --features studies) or set RBSS=..."
step "states and rbss's numbers from $RBSS (paper, eval, ik, inverse-dynamics)"
"$VENV/bin/python" "$HERE/peers.py" states "$BUILD" "$RBSS"

# ---- 4. checks and timing, back to back --------------------------------------------------------
step "harness: agreement checks and timing of Pinocchio and MuJoCo"
"$BUILD/harness" "$BUILD/states.txt" "$BUILD/stewart_6ups.xml" "$BUILD/results.txt" \
  "$(cat "$BUILD/timing_state.txt")" || die "the harness failed"
step "rbss bench solvers --model stewart_6ups"
rm -rf "$BUILD/rbss_bench"
"$RBSS" bench solvers --model stewart_6ups --out "$BUILD/rbss_bench" >"$BUILD/rbss_bench.log" 2>&1 ||
  die "rbss bench solvers failed: $(tail -n 5 "$BUILD/rbss_bench.log")"
[[ -f $BUILD/rbss_bench/solvers.csv ]] || die "rbss bench solvers wrote no solvers.csv"

# ---- 5. the report -----------------------------------------------------------------------------
step "RESULT.md, peers.csv"
"$VENV/bin/python" "$HERE/peers.py" report "$BUILD" "$HERE" "$RBSS"
echo "bench/peers: wrote $HERE/RESULT.md and $HERE/peers.csv" >&2
