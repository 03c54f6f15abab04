#!/usr/bin/env bash
# bench/peers/run.sh -- rbss beside Pinocchio and MuJoCo on the paper's 6-UPS (see README.md).
#
#   bench/peers/run.sh            # from anywhere; needs target/release/rbss (cargo build --release)
#   PEERS_CODEGEN=0 bench/peers/run.sh   # without Pinocchio's generated code (CppADCodeGen)
#   RBSS_NATIVE=target/native/release/rbss bench/peers/run.sh   # + rbss built with target-cpu=native
#
# Steps: venv with pin / mujoco-core / cmeel-eigen (+ cmeel-cppad / cmeel-cppadcodegen) from PyPI
# (reused when present) -> C++ harness (rebuilt when harness.cpp or stewart_pin.hpp changes) ->
# Pinocchio's generated constraintDynamics: generator, C sources, the C compiled portable and
# -march=native, its harness (each rebuilt when its inputs change) -> states and rbss's numbers
# from the rbss CLI -> harness: agreement checks and timing -> codegen harness: the same for the
# generated code -> `rbss bench solvers` right after, three rounds (the portable rbss, then the
# native one when RBSS_NATIVE is set) -> RESULT.md, peers.csv.
# Environment: RBSS (the rbss binary), PYTHON (the interpreter for the venv, python3 >= 3.11),
# PEERS_CODEGEN (1, the default: include the generated-code peer; 0: skip it), RBSS_NATIVE (unset,
# the default: no native rbss; else an rbss built with RUSTFLAGS="-C target-cpu=native", timed
# right after the portable one and compared with the generated C built with -march=native).
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
RBSS=${RBSS:-$ROOT/target/release/rbss}
RBSS_NATIVE=${RBSS_NATIVE:-}
PYTHON=${PYTHON:-python3}
VENV=$HERE/.venv
BUILD=$HERE/build
PEERS_CODEGEN=${PEERS_CODEGEN:-1}
[[ $PEERS_CODEGEN == 0 || $PEERS_CODEGEN == 1 ]] || { echo "bench/peers: ERROR: PEERS_CODEGEN must be 0 or 1" >&2; exit 1; }

die() { echo "bench/peers: ERROR: $*" >&2; exit 1; }
step() { echo "==> $*" >&2; }
trap 'die "failed at line $LINENO: $BASH_COMMAND"' ERR

# ---- 1. the venv (idempotent; bench/peers/venv.sh) ---------------------------------------------
source "$HERE/venv.sh"
want="pin==$PIN_VERSION mujoco-core==$MUJOCO_VERSION cmeel-eigen==$EIGEN_VERSION"
[[ $PEERS_CODEGEN == 1 ]] && want+=" cmeel-cppad==$CPPAD_VERSION cmeel-cppadcodegen==$CPPADCG_VERSION"
peers_venv $want
peers_flags   # CMEEL, MJ, MJLIB, CXXFLAGS, LDFLAGS (venv.sh)
# ---- 2. the harness (rebuilt when the source or the flags change) ------------------------------
mkdir -p "$BUILD"
# compiles run under `nice` (the timing runs do not)
stamp="$(g++ --version | head -n1) ${CXXFLAGS[*]} ${LDFLAGS[*]} $(cat "$HERE/harness.cpp" "$HERE/stewart_pin.hpp" "$HERE/stewart_mj.hpp" | sha256sum | cut -d' ' -f1)"
if [[ ! -x $BUILD/harness || ! -f $BUILD/harness.stamp || $(cat "$BUILD/harness.stamp") != "$stamp" ]]; then
  step "g++ harness.cpp (Pinocchio is header-heavy: 1 to 2 minutes)"
  nice -n "$PEERS_NICE" g++ "${CXXFLAGS[@]}" "$HERE/harness.cpp" -o "$BUILD/harness" "${LDFLAGS[@]}" ||
    die "compiling harness.cpp failed"
  echo "$stamp" >"$BUILD/harness.stamp"
fi

# ---- 2b. Pinocchio's generated code (PEERS_CODEGEN=1; each piece rebuilt when its inputs change)
CG=$BUILD/codegen
rm -f "$CG/results.txt"   # never report a previous run's generated peer
if [[ $PEERS_CODEGEN == 1 ]]; then
  mkdir -p "$CG"
  CG_SRC=$CG/src/constraintDynamics_forward_zero.c
  peers_codegen_gen || die "compiling codegen_gen.cpp failed (PEERS_CODEGEN=0 skips this peer): $(tail -n 5 "$CG/codegen_gen.log")"
  step "codegen_gen: Pinocchio's CodeGenConstraintDynamics -> $CG/src"
  rm -rf "$CG/src" && mkdir -p "$CG/src"
  "$CG/codegen_gen" "$CG/src" >"$CG/gen_info.txt" || die "codegen_gen failed"
  [[ -f $CG_SRC ]] || die "codegen_gen wrote no $CG_SRC"
  # the generated C, twice: portable (-O3, no -march, like rbss and the harnesses) and native;
  # the function is renamed so that both link into one harness
  CG_PORTABLE=(-O3 -DNDEBUG)
  CG_NATIVE=(-O3 -march=native -DNDEBUG)
  NATIVE_MARCH=$(gcc -march=native -Q --help=target 2>/dev/null | awk '$1 == "-march=" {print $2}')
  for build in portable native; do
    if [[ $build == portable ]]; then flags=("${CG_PORTABLE[@]}"); else flags=("${CG_NATIVE[@]}"); fi
    stamp="$(gcc --version | head -n1) ${flags[*]} ($NATIVE_MARCH) $(sha256sum "$CG_SRC" | cut -d' ' -f1)"
    if [[ ! -f $CG/cd_$build.o || ! -f $CG/cd_$build.stamp || $(cat "$CG/cd_$build.stamp") != "$stamp" ]]; then
      step "gcc ${flags[*]} constraintDynamics_forward_zero.c ($build)"
      nice -n "$PEERS_NICE" gcc "${flags[@]}" -DconstraintDynamics_forward_zero=cg_cd_$build -c "$CG_SRC" \
        -o "$CG/cd_$build.o" || die "compiling the generated C ($build) failed"
      echo "$stamp" >"$CG/cd_$build.stamp"
    fi
    echo "cg_flags_$build ${flags[*]}" >>"$CG/gen_info.txt"
  done
  echo "cg_gcc $(gcc --version | head -n1)" >>"$CG/gen_info.txt"
  echo "cg_native_march $NATIVE_MARCH" >>"$CG/gen_info.txt"
  # its harness (flags of harness.cpp: no -march; see codegen_harness.cpp)
  stamp="$(g++ --version | head -n1) ${CXXFLAGS[*]} $(cat "$HERE/codegen_harness.cpp" "$HERE/stewart_pin.hpp" | sha256sum | cut -d' ' -f1)"
  if [[ ! -f $CG/codegen_harness.o || ! -f $CG/codegen_harness.stamp || $(cat "$CG/codegen_harness.stamp") != "$stamp" ]]; then
    step "g++ codegen_harness.cpp (about 40 s)"
    nice -n "$PEERS_NICE" g++ "${CXXFLAGS[@]}" -c "$HERE/codegen_harness.cpp" -o "$CG/codegen_harness.o" ||
      die "compiling codegen_harness.cpp failed"
    echo "$stamp" >"$CG/codegen_harness.stamp"
  fi
  g++ "$CG/codegen_harness.o" "$CG/cd_portable.o" "$CG/cd_native.o" -o "$CG/codegen_harness" \
    -L"$CMEEL/lib" -lpinocchio_default -Wl,-rpath,"$CMEEL/lib" || die "linking codegen_harness failed"
fi

# ---- 3. rbss's numbers --------------------------------------------------------------------------
[[ -x $RBSS ]] || die "$RBSS not found: build it first (cargo build --release --features studies) or set RBSS=..."
if [[ -n $RBSS_NATIVE ]]; then
  [[ -x $RBSS_NATIVE ]] || die "RBSS_NATIVE=$RBSS_NATIVE not found: build it first (RUSTFLAGS=\"-C target-cpu=native\" cargo build --release --features studies --target-dir target/native)"
  RBSS_NATIVE=$(realpath "$RBSS_NATIVE")
  [[ $RBSS_NATIVE != $(realpath "$RBSS") ]] || die "RBSS_NATIVE is the same binary as RBSS ($RBSS)"
fi
step "states and rbss's numbers from $RBSS (paper, eval, ik, inverse-dynamics)"
"$VENV/bin/python" "$HERE/peers.py" states "$BUILD" "$RBSS"

# ---- 4. checks and timing, back to back --------------------------------------------------------
# the timing window's start and end (UTC, load averages), for RESULT.md
window() { echo "$1 $(date -u '+%Y-%m-%d %H:%M:%S') $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo '? ? ?')"; }
window start >"$BUILD/timing_window.txt"
step "harness: agreement checks and timing of Pinocchio and MuJoCo"
"$BUILD/harness" "$BUILD/states.txt" "$BUILD/stewart_6ups.xml" "$BUILD/results.txt" \
  "$(cat "$BUILD/timing_state.txt")" || die "the harness failed"
if [[ $PEERS_CODEGEN == 1 ]]; then
  step "codegen harness: agreement checks and timing of Pinocchio's generated constraintDynamics"
  "$CG/codegen_harness" "$BUILD/states.txt" "$CG/results.txt" "$(cat "$BUILD/timing_state.txt")" ||
    die "the codegen harness failed"
fi
# three rounds, alternating the portable and the native binary; the report takes each build's median
rm -rf "$BUILD/rbss_bench" "$BUILD/rbss_bench_native" "$BUILD"/rbss_bench*.log   # never report a previous run's
bins=(portable "$RBSS")
if [[ -n $RBSS_NATIVE ]]; then bins+=(native "$RBSS_NATIVE"); fi
for round in 1 2 3; do
  for ((k = 0; k < ${#bins[@]}; k += 2)); do
    b=${bins[k]} bin=${bins[k + 1]}
    if [[ $b == native ]]; then dir=$BUILD/rbss_bench_native/r$round; else dir=$BUILD/rbss_bench/r$round; fi
    log=$BUILD/rbss_bench_${b}_r$round.log
    step "rbss bench solvers --model stewart_6ups ($b, round $round of 3: $bin)"
    "$bin" bench solvers --model stewart_6ups --out "$dir" >"$log" 2>&1 ||
      die "rbss bench solvers ($bin) failed: $(tail -n 5 "$log")"
    [[ -f $dir/solvers.csv ]] || die "rbss bench solvers ($bin) wrote no $dir/solvers.csv"
  done
done
window end >>"$BUILD/timing_window.txt"

# ---- 5. the report -----------------------------------------------------------------------------
step "RESULT.md, peers.csv"
"$VENV/bin/python" "$HERE/peers.py" report "$BUILD" "$HERE" "$RBSS" ${RBSS_NATIVE:+"$RBSS_NATIVE"}
echo "bench/peers: wrote $HERE/RESULT.md and $HERE/peers.csv" >&2
