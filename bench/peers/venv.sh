# bench/peers/venv.sh -- sourced by run.sh and import.sh: the pinned versions and `peers_venv`,
# which makes $VENV (python3 >= 3.11 from $PYTHON) and pip-installs the packages it is given
# when `pip freeze` lacks one of them (reused otherwise). The caller defines die, step, VENV and
# PYTHON.
PIN_VERSION=4.1.0
MUJOCO_VERSION=4.0.0     # the `mujoco` 4.0.0 wheel is pure Python; `mujoco-core` ships libmujoco + headers
EIGEN_VERSION=3.4.1
CPPAD_VERSION=20250000.2       # cmeel-cppad: CppAD headers + libcppad_lib
CPPADCG_VERSION=2.4.3          # cmeel-cppadcodegen: CppADCodeGen headers
PEERS_NICE=${PEERS_NICE:-10}  # the niceness of the compiles (the timing runs are not niced)

peers_venv() {
  local want="$*" have missing=0 p
  step "venv $VENV"
  if [[ ! -x $VENV/bin/python ]]; then
    command -v "$PYTHON" >/dev/null || die "$PYTHON not found (set PYTHON=python3.11 or newer)"
    "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' ||
      die "$PYTHON is older than 3.11 (mujoco-core $MUJOCO_VERSION needs >= 3.11)"
    "$PYTHON" -m venv "$VENV" || die "could not create the venv (python3-venv missing?)"
  fi
  have=$("$VENV/bin/python" -m pip freeze 2>/dev/null || true)
  for p in $want; do grep -qix "$p" <<<"$have" || missing=1; done
  if [[ $missing == 1 ]]; then
    step "pip install $want (PyPI)"
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check $want ||
      die "pip install failed: is PyPI reachable? ($want)"
  fi
}

# The wheels' paths and the harnesses' flags (run.sh, run_derivatives.sh): sets CMEEL, MJ, MJLIB,
# CXXFLAGS, LDFLAGS. Needs $VENV.
peers_flags() {
  local site
  site=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
  CMEEL=$site/cmeel.prefix
  MJ=$site/mujoco
  MJLIB=$(ls "$MJ"/libmujoco.so.* 2>/dev/null | head -n1 || true)
  [[ -f $CMEEL/include/pinocchio/algorithm/constrained-dynamics.hpp ]] || die "Pinocchio headers missing in $CMEEL"
  [[ -f $CMEEL/lib/libpinocchio_default.so ]] || die "libpinocchio_default.so missing in $CMEEL/lib"
  [[ -f $CMEEL/include/eigen3/Eigen/Dense ]] || die "Eigen headers missing in $CMEEL/include/eigen3"
  [[ -n $MJLIB && -f $MJ/include/mujoco/mujoco.h ]] ||
    die "libmujoco.so.* or mujoco/mujoco.h missing in $MJ (does the mujoco-core wheel still ship them?)"
  command -v g++ >/dev/null || die "g++ not found"
  CXXFLAGS=(-std=c++17 -O3 -DNDEBUG -Wno-deprecated-declarations
    -DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION -DBOOST_MPL_LIMIT_LIST_SIZE=30
    -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS
    -DBOOST_FUSION_INVOKE_MAX_ARITY=12
    -I"$CMEEL/include" -I"$CMEEL/include/eigen3" -I"$MJ/include")
  LDFLAGS=(-L"$CMEEL/lib" -lpinocchio_default "$MJLIB" -Wl,-rpath,"$CMEEL/lib" -Wl,-rpath,"$MJ")
}

# Pinocchio's code generator, $BUILD/codegen/codegen_gen (codegen_gen.cpp: constraintDynamics or,
# with `derivatives`, its derivatives), compiled when missing or when its inputs changed; shared by
# run.sh and run_derivatives.sh. Returns non-zero (the compiler's messages in
# $BUILD/codegen/codegen_gen.log) when it does not compile. Needs peers_flags.
peers_codegen_gen() {
  local cg=$BUILD/codegen stamp
  [[ -f $CMEEL/include/cppad/cg.hpp && -f $CMEEL/include/pinocchio/codegen/cppadcg-algo.hpp ]] ||
    die "CppADCodeGen or Pinocchio's codegen headers missing in $CMEEL/include (PEERS_CODEGEN=0 skips this peer)"
  [[ -f $CMEEL/lib/libcppad_lib.so ]] || die "libcppad_lib.so missing in $CMEEL/lib (cmeel-cppad)"
  command -v gcc >/dev/null || die "gcc not found"
  mkdir -p "$cg"
  # CppAD<CG<double>> instantiations of Pinocchio; -O1 is enough (it runs in a second)
  GENFLAGS=("${CXXFLAGS[@]/-O3/-O1}")
  stamp="$(g++ --version | head -n1) ${GENFLAGS[*]} pin $PIN_VERSION cppad $CPPAD_VERSION cppadcg $CPPADCG_VERSION $(cat "$HERE/codegen_gen.cpp" "$HERE/stewart_pin.hpp" | sha256sum | cut -d' ' -f1)"
  if [[ ! -x $cg/codegen_gen || ! -f $cg/codegen_gen.stamp || $(cat "$cg/codegen_gen.stamp") != "$stamp" ]]; then
    step "g++ codegen_gen.cpp (Pinocchio on CppAD<CG<double>>: 2 to 6 minutes)"
    nice -n "$PEERS_NICE" g++ "${GENFLAGS[@]}" "$HERE/codegen_gen.cpp" -o "$cg/codegen_gen" \
      -L"$CMEEL/lib" -lpinocchio_default -lcppad_lib -ldl -Wl,-rpath,"$CMEEL/lib" 2>"$cg/codegen_gen.log" ||
      return 1
    echo "$stamp" >"$cg/codegen_gen.stamp"
  fi
}
