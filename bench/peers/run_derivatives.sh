#!/usr/bin/env bash
# bench/peers/run_derivatives.sh -- the derivative peers of issue 36 on the paper's 6-UPS, beside
# rbss's derivatives, in one run (see README.md, "Derivatives").
#
#   cargo build --release --features studies          # target/release/rbss (the states)
#   cargo build --release -p rbss-runtime --example peers_derivatives
#   bench/peers/run_derivatives.sh
#   PEERS_CODEGEN=0 bench/peers/run_derivatives.sh     # without Pinocchio's generated derivatives
#   # + rbss built for this machine's CPU (its own target directory under target/):
#   RUSTFLAGS="-C target-cpu=native" cargo build --release -p rbss-runtime --example peers_derivatives --target-dir target/native
#   RBSS_DERIV_NATIVE=target/native/release/examples/peers_derivatives bench/peers/run_derivatives.sh
#
# Steps: venv (venv.sh) -> states and rbss's numbers from the rbss CLI (peers.py states) ->
# Pinocchio's generated derivatives (codegen_gen.cpp ... derivatives; the C compiled portable
# and -march=native; when any of it fails, the run goes on without that peer and says why) ->
# deriv_harness.cpp -> DERIV_ROUNDS rounds (default 3), each: rbss's peers_derivatives example
# (portable, then native when RBSS_DERIV_NATIVE is set: derivatives at every state + timings),
# then the harness (agreement + timings of the peers), the load average before each ->
# deriv_report.py: derivatives.csv and the "Derivatives" section of RESULT.md.
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
RBSS=${RBSS:-$ROOT/target/release/rbss}
RBSS_DERIV=${RBSS_DERIV:-$ROOT/target/release/examples/peers_derivatives}
RBSS_DERIV_NATIVE=${RBSS_DERIV_NATIVE:-}
PYTHON=${PYTHON:-python3}
VENV=$HERE/.venv
BUILD=$HERE/build
OUT=$BUILD/deriv
PEERS_CODEGEN=${PEERS_CODEGEN:-1}
DERIV_ROUNDS=${DERIV_ROUNDS:-3}
DT=0.001   # the step of rbss's step Jacobians = MuJoCo's timestep (stewart_mj.hpp)
[[ $PEERS_CODEGEN == 0 || $PEERS_CODEGEN == 1 ]] || { echo "bench/peers: ERROR: PEERS_CODEGEN must be 0 or 1" >&2; exit 1; }
[[ $DERIV_ROUNDS =~ ^[1-9][0-9]*$ ]] || { echo "bench/peers: ERROR: DERIV_ROUNDS must be a positive integer" >&2; exit 1; }

die() { echo "bench/peers: ERROR: $*" >&2; exit 1; }
step() { echo "==> $*" >&2; }
trap 'die "failed at line $LINENO: $BASH_COMMAND"' ERR

source "$HERE/venv.sh"
want="pin==$PIN_VERSION mujoco-core==$MUJOCO_VERSION cmeel-eigen==$EIGEN_VERSION"
[[ $PEERS_CODEGEN == 1 ]] && want+=" cmeel-cppad==$CPPAD_VERSION cmeel-cppadcodegen==$CPPADCG_VERSION"
peers_venv $want
peers_flags   # CMEEL, MJ, MJLIB, CXXFLAGS, LDFLAGS (venv.sh)
[[ -f $CMEEL/include/pinocchio/algorithm/constrained-dynamics-derivatives.hpp ]] ||
  die "pinocchio/algorithm/constrained-dynamics-derivatives.hpp missing in $CMEEL/include"
[[ -x $RBSS ]] || die "$RBSS not found: cargo build --release --features studies (or set RBSS=...)"
[[ -x $RBSS_DERIV ]] || die "$RBSS_DERIV not found: cargo build --release -p rbss-runtime --example peers_derivatives (or set RBSS_DERIV=...)"
if [[ -n $RBSS_DERIV_NATIVE ]]; then
  [[ -x $RBSS_DERIV_NATIVE ]] || die "RBSS_DERIV_NATIVE=$RBSS_DERIV_NATIVE not found"
  [[ $(realpath "$RBSS_DERIV_NATIVE") != $(realpath "$RBSS_DERIV") ]] || die "RBSS_DERIV_NATIVE is the same binary as RBSS_DERIV"
fi
mkdir -p "$BUILD" "$OUT"
rm -f "$OUT"/*.txt

# ---- Pinocchio's generated derivatives (PEERS_CODEGEN=1) ----------------------------------------
CG=$BUILD/codegen
CG_OK=0
cg_fail() { echo "$*" >"$OUT/cg_status.txt"; echo "bench/peers: the generated-derivatives peer is left out: $*" >&2; }
if [[ $PEERS_CODEGEN == 1 ]]; then
  mkdir -p "$CG"
  if peers_codegen_gen; then   # venv.sh: the generator shared with run.sh
    step "codegen_gen derivatives: Pinocchio's CodeGenConstraintDynamicsDerivatives -> $CG/dsrc"
    rm -rf "$CG/dsrc" && mkdir -p "$CG/dsrc"
    DSRC=$CG/dsrc/constraintDynamicsDerivatives_forward_zero.c
    if ! "$CG/codegen_gen" "$CG/dsrc" derivatives >"$CG/dgen_info.txt" 2>"$CG/dgen.log"; then
      cg_fail "codegen_gen derivatives failed: $(tail -n 3 "$CG/dgen.log" | tr '\n' ' ')"
    elif [[ ! -f $DSRC ]]; then
      cg_fail "codegen_gen derivatives wrote no $DSRC"
    else
      CG_OK=1
      NATIVE_MARCH=$(gcc -march=native -Q --help=target 2>/dev/null | awk '$1 == "-march=" {print $2}')
      for build in portable native; do
        if [[ $build == portable ]]; then flags=(-O3 -DNDEBUG); else flags=(-O3 -march=native -DNDEBUG); fi
        stamp="$(gcc --version | head -n1) ${flags[*]} ($NATIVE_MARCH) $(sha256sum "$DSRC" | cut -d' ' -f1)"
        if [[ ! -f $CG/dcd_$build.o || ! -f $CG/dcd_$build.stamp || $(cat "$CG/dcd_$build.stamp") != "$stamp" ]]; then
          step "gcc ${flags[*]} constraintDynamicsDerivatives_forward_zero.c ($build; $(wc -l <"$DSRC") lines)"
          if ! nice -n "$PEERS_NICE" gcc "${flags[@]}" -DconstraintDynamicsDerivatives_forward_zero=cg_dcd_$build -c "$DSRC" \
            -o "$CG/dcd_$build.o" 2>"$CG/dcd_$build.log"; then
            cg_fail "gcc ${flags[*]} on the generated derivatives failed: $(tail -n 3 "$CG/dcd_$build.log" | tr '\n' ' ')"
            CG_OK=0
            break
          fi
          echo "$stamp" >"$CG/dcd_$build.stamp"
        fi
        echo "cg_flags_$build ${flags[*]}" >>"$CG/dgen_info.txt"
      done
      echo "cg_native_march $NATIVE_MARCH" >>"$CG/dgen_info.txt"
      echo "cg_c_lines $(wc -l <"$DSRC")" >>"$CG/dgen_info.txt"
    fi
  else
    cg_fail "compiling codegen_gen.cpp failed (see $CG/codegen_gen.log)"
  fi
else
  echo "PEERS_CODEGEN=0" >"$OUT/cg_status.txt"
fi

# ---- the harness (rebuilt when its sources, the flags or the generated objects change) ----------
# (the generated functions are weak symbols in it: linked in when they were built)
hflags=("${CXXFLAGS[@]}")
hobjs=()
if [[ $CG_OK == 1 ]]; then hobjs=("$CG/dcd_portable.o" "$CG/dcd_native.o"); fi
stamp="$(g++ --version | head -n1) ${hflags[*]} ${LDFLAGS[*]} $(cat "$HERE/deriv_harness.cpp" "$HERE/stewart_pin.hpp" "$HERE/stewart_mj.hpp" | sha256sum | cut -d' ' -f1)"
if [[ ! -f $BUILD/deriv_harness.o || ! -f $BUILD/deriv_harness.stamp || $(cat "$BUILD/deriv_harness.stamp") != "$stamp" ]]; then
  step "g++ deriv_harness.cpp (Pinocchio is header-heavy: 1 to 3 minutes)"
  nice -n "$PEERS_NICE" g++ "${hflags[@]}" -c "$HERE/deriv_harness.cpp" -o "$BUILD/deriv_harness.o" ||
    die "compiling deriv_harness.cpp failed"
  echo "$stamp" >"$BUILD/deriv_harness.stamp"
fi
g++ "$BUILD/deriv_harness.o" "${hobjs[@]}" -o "$BUILD/deriv_harness" "${LDFLAGS[@]}" || die "linking deriv_harness failed"

# ---- states (rbss's CLI, as run.sh) -------------------------------------------------------------
step "states from $RBSS"
"$VENV/bin/python" "$HERE/peers.py" states "$BUILD" "$RBSS"
TI=$(cat "$BUILD/timing_state.txt")

# ---- rounds: rbss (portable, native), then the peers; the load before each ---------------------
for ((r = 1; r <= DERIV_ROUNDS; r++)); do
  echo "round $r start $(date -u '+%Y-%m-%d %H:%M:%S') $(cut -d' ' -f1-3 /proc/loadavg)" >>"$OUT/rounds.txt"
  step "round $r of $DERIV_ROUNDS: rbss peers_derivatives (portable)"
  "$RBSS_DERIV" "$BUILD/states.txt" "$OUT/rbss_portable_r$r.txt" "$TI" "$DT" || die "peers_derivatives failed"
  if [[ -n $RBSS_DERIV_NATIVE ]]; then
    step "round $r: rbss peers_derivatives (native)"
    "$RBSS_DERIV_NATIVE" "$BUILD/states.txt" "$OUT/rbss_native_r$r.txt" "$TI" "$DT" || die "peers_derivatives (native) failed"
  fi
  step "round $r: deriv_harness (Pinocchio, generated Pinocchio, MuJoCo)"
  "$BUILD/deriv_harness" "$BUILD/states.txt" "$OUT/rbss_portable_r$r.txt" "$BUILD/stewart_6ups_motors.xml" \
    "$OUT/peers_r$r.txt" "$TI" || die "deriv_harness failed"
  echo "round $r end $(date -u '+%Y-%m-%d %H:%M:%S') $(cut -d' ' -f1-3 /proc/loadavg)" >>"$OUT/rounds.txt"
done

step "derivatives.csv, RESULT.md (section Derivatives)"
"$VENV/bin/python" "$HERE/deriv_report.py" "$BUILD" "$HERE" "$RBSS_DERIV" ${RBSS_DERIV_NATIVE:+"$RBSS_DERIV_NATIVE"}
echo "bench/peers: wrote $HERE/derivatives.csv and the Derivatives section of $HERE/RESULT.md" >&2
