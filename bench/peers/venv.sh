# bench/peers/venv.sh -- sourced by run.sh and import.sh: the pinned versions and `peers_venv`,
# which makes $VENV (python3 >= 3.11 from $PYTHON) and pip-installs the packages it is given
# when `pip freeze` lacks one of them (reused otherwise). The caller defines die, step, VENV and
# PYTHON.
PIN_VERSION=4.1.0
MUJOCO_VERSION=4.0.0     # the `mujoco` 4.0.0 wheel is pure Python; `mujoco-core` ships libmujoco + headers
EIGEN_VERSION=3.4.1
CPPAD_VERSION=20250000.2       # cmeel-cppad: CppAD headers + libcppad_lib
CPPADCG_VERSION=2.4.3          # cmeel-cppadcodegen: CppADCodeGen headers

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
