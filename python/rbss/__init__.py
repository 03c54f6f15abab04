"""rbss from Python: a robot compiled from its model file, called through its C ABI.

    import rbss
    robot = rbss.compile("models/stewart_6ups.toml")   # generated, compiled, cached (rbss library)
    x = robot.ik([0.1, 0, 0.94, 0.1, 0, 0])             # numpy arrays in and out
    xddot, lam = robot.forward_dynamics(x, np.zeros(robot.n), np.zeros(robot.actuated))

Two implementations of one API over the library's C ABI (ffi/include/rbss.h, version 4):
`rbss._native` (python/native: PyO3, compiled once for every robot when the package is installed,
`pip install ./python`; it loads the library and calls its functions, under 1 us per call over
the library) when it is importable, else a thin ctypes + numpy layer (about 8 us per call over;
used from a source tree without a build, PYTHONPATH=python). `rbss.compile(..., backend="ctypes")`
picks one; `repr(robot)` says which. Every method checks shapes, calls the library and raises
RbssError with rbss's message on a failure. Batched inputs of shape (k, n) are accepted by every
method and looped in the library (forward_dynamics: rbss_forward_dynamics_batch) or, with
ctypes, once per row from Python. The vector methods take `out=` (an array, or a tuple for two
results) to write into instead of allocating.

Threads: a robot may be shared between threads, with either implementation. The C ABI allows
one call at a time on a handle; `rbss._native` calls the library with the GIL held, the ctypes
layer (which releases the GIL during a call) takes the robot's lock around each call and its
error message. Calls on one robot therefore run one after the other; for calls in parallel,
give each thread its own robot (`rbss.compile` again: the library is loaded once, each robot
has its own handle).
"""

import ctypes
import os
import shutil
import subprocess
import threading

import numpy as np

from . import _abi

try:
    from . import _native
except ImportError:  # not installed (pip install ./python builds it; PYTHONPATH=python has none)
    _native = None

__all__ = [
    "RbssError",
    "Robot",
    "NativeRobot",
    "compile",
    "ABI_VERSION",
    "native_available",
    "RBSS_ERR_SOLVER",
    "RBSS_ERR_ARGUMENT",
    "RBSS_ERR_STATE",
    "RBSS_ERR_NONFINITE",
]

ABI_VERSION = _abi.ABI_VERSION
# RbssError.code's values (rbss.h's RBSS_ERR_*).
RBSS_ERR_SOLVER = _abi.RBSS_ERR_SOLVER
RBSS_ERR_ARGUMENT = _abi.RBSS_ERR_ARGUMENT
RBSS_ERR_STATE = _abi.RBSS_ERR_STATE
RBSS_ERR_NONFINITE = _abi.RBSS_ERR_NONFINITE

# The ctypes types of the C ABI's kinds (rbss-abi; python/rbss/_abi.py is its table). Arrays go
# as addresses (c_void_p): cheaper per call than ctypes pointer objects.
_H = ctypes.c_void_p
_ARG_TYPES = {
    "handle": _H,
    "handle_const": _H,
    "input": ctypes.c_void_p,
    "input_or_null": ctypes.c_void_p,
    "output": ctypes.c_void_p,
    "int": ctypes.c_int,
    "size": ctypes.c_size_t,
    "double": ctypes.c_double,
}
_RETURN_TYPES = {
    "int": ctypes.c_int,
    "size": ctypes.c_size_t,
    "u32": ctypes.c_uint32,
    "string": ctypes.c_char_p,
    "handle": _H,
    "void": None,
}


def _declare(lib, library_path):
    """Sets every function of the C ABI's table on `lib` (argtypes, restype)."""
    for name, (ret, args) in _abi.FUNCTIONS.items():
        try:
            fn = getattr(lib, name)
        except AttributeError:
            raise RbssError(-1, f"{library_path}: no function {name} (C ABI {ABI_VERSION})") from None
        fn.argtypes = [_ARG_TYPES[kind] for _, kind, _ in args]
        fn.restype = _RETURN_TYPES[ret]


class RbssError(Exception):
    """A failed call: `code` (rbss.h's RBSS_ERR_*) and rbss's message."""

    def __init__(self, code, message):
        super().__init__(message)
        self.code = code
        self.message = message


def _rbss_command():
    exe = os.environ.get("RBSS") or shutil.which("rbss")
    if not exe:
        raise RbssError(-1, "the `rbss` command is not found: set RBSS to its path or put it on PATH")
    return exe


def native_available():
    """Whether the PyO3 core (rbss._native) is importable."""
    return _native is not None


def compile(model_file, backend=None):
    """The robot of `model_file`, compiled into a library (cached as `rbss --model-file` does).

    backend: "native" (rbss._native, PyO3), "ctypes", or None: native when importable."""
    if backend not in (None, "native", "ctypes"):
        raise ValueError(f"backend: expected 'native', 'ctypes' or None, got {backend!r}")
    if backend == "native" and _native is None:
        raise RbssError(-1, "rbss._native is not installed: pip install ./python (python/README.md)")
    out = subprocess.run(
        [_rbss_command(), "library", "--model-file", os.fspath(model_file)],
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:
        raise RbssError(-1, out.stderr.strip())
    path = out.stdout.strip()
    if backend == "ctypes" or _native is None:
        return Robot(path)
    return NativeRobot(path)


def _roundtrip(robot, x, xdot, xddot):
    u, _ = robot.inverse_dynamics(x, xdot, xddot)
    back, _ = robot.forward_dynamics(x, xdot, u)
    return float(np.max(np.abs(back - np.asarray(xddot))))


if _native is not None:

    class NativeRobot(_native.Robot):
        """A robot's library through rbss._native (PyO3): the API of `Robot`, the checks and
        loops in Rust. Thread-safe: the library is called with the GIL held, one call at a time
        (rbss.h allows one per handle)."""

        backend = "native"

        def roundtrip(self, x, xdot, xddot):
            """The paper's round trip at a state: inverse dynamics, then forward dynamics under
            its forces; returns max |Xddot_forward - xddot|."""
            return _roundtrip(self, x, xdot, xddot)

        def __repr__(self):
            return f"<rbss robot {self.name!r} (native, PyO3) from {self.library_path}>"

else:
    NativeRobot = None


# simulate's integrators: rbss.h's RBSS_METHOD_*.
_METHODS = {"dopri5": _abi.RBSS_METHOD_DOPRI5, "dop853": _abi.RBSS_METHOD_DOP853}


def _method_code(method):
    if method not in _METHODS:
        raise ValueError(f"method: expected 'dopri5' or 'dop853', got {method!r}")
    return _METHODS[method]


# linearize's coordinates and step_derivatives' steps: rbss.h's RBSS_LINEARIZE_* and RBSS_STEP_*.
_COORDINATES = {"outputs": _abi.RBSS_LINEARIZE_OUTPUTS, "actuated": _abi.RBSS_LINEARIZE_ACTUATED}
_STEPS = {"rk4": _abi.RBSS_STEP_RK4, "semi_implicit_euler": _abi.RBSS_STEP_SEMI_IMPLICIT_EULER}


def _code(table, value, what):
    if value not in table:
        expected = " or ".join(repr(k) for k in table)
        raise ValueError(f"{what}: expected {expected}, got {value!r}")
    return table[value]


# forward_dynamics_derivatives' results, in the order of rbss_forward_dynamics_derivatives.
_FD_DERIVATIVES = (
    "xddot",
    "lambda",
    "dxddot_dx",
    "dxddot_dxdot",
    "dxddot_du",
    "dlambda_dx",
    "dlambda_dxdot",
    "dlambda_du",
)


# inverse_dynamics_derivatives' results, in the order of rbss_inverse_dynamics_derivatives.
_ID_DERIVATIVES = (
    "u",
    "lambda",
    "du_dx",
    "du_dxdot",
    "du_dxddot",
    "dlambda_dx",
    "dlambda_dxdot",
    "dlambda_dxddot",
)


def _shaped(flat, rows, cols):
    """Column-major (rows x cols) matrices, one per row of `flat`, as numpy's (..., rows, cols)
    (a view); cols None: a vector, as it is."""
    if cols is None:
        return flat
    return np.swapaxes(flat.reshape(flat.shape[:-1] + (cols, rows)), -1, -2)


def _ptr(a):
    return a.__array_interface__["data"][0]


def _plain(a, length):
    """True for a C-contiguous float64 numpy vector of `length` (no copy needed)."""
    return (
        type(a) is np.ndarray
        and a.dtype == np.float64
        and a.shape == (length,)
        and a.flags.c_contiguous
    )


class Robot:
    """A robot's library, loaded through ctypes: sizes and names as attributes, solvers as
    methods. Thread-safe: each call on the handle, with its error message, holds the robot's
    lock (ctypes releases the GIL during the call; rbss.h allows one call at a time per
    handle)."""

    backend = "ctypes"

    def __init__(self, library_path):
        self.library_path = library_path
        lib = ctypes.CDLL(library_path)
        lib.rbss_abi_version.restype = ctypes.c_uint32
        if lib.rbss_abi_version() != ABI_VERSION:
            raise RbssError(-1, f"{library_path}: C ABI {lib.rbss_abi_version()}, expected {ABI_VERSION}")
        _declare(lib, library_path)
        self._lib = lib
        # One call at a time on the handle (rbss.h): the lock is held across the call and the
        # read of its error message.
        self._lock = threading.Lock()
        h = lib.rbss_new()
        if not h:
            raise RbssError(-1, lib.rbss_last_error(None).decode())
        self._h = _H(h)
        size = lambda what: lib.rbss_size(self._h, what)  # noqa: E731
        self.n, self.m = size(_abi.RBSS_COORDINATES), size(_abi.RBSS_CONSTRAINTS)
        self.actuated, self.outputs = size(_abi.RBSS_ACTUATED), size(_abi.RBSS_OUTPUTS)
        self.has_dynamics = bool(size(_abi.RBSS_DYNAMICS))
        self.name = lib.rbss_name(self._h).decode()
        self.coordinates = [lib.rbss_coordinate(self._h, i).decode() for i in range(self.n)]
        self.constraint_names = [lib.rbss_constraint(self._h, i).decode() for i in range(self.m)]
        self.actuated_index = [lib.rbss_actuated(self._h, i) for i in range(self.actuated)]
        self.output_index = [lib.rbss_output(self._h, i) for i in range(self.outputs)]
        self.home = np.empty(self.n)
        self._call("rbss_home", _ptr(self.home))
        # The bound functions, looked up once (the per-call cost is the call itself).
        self._fd = lib.rbss_forward_dynamics

    def __repr__(self):
        return f"<rbss robot {self.name!r} (ctypes) from {self.library_path}>"

    def __del__(self):
        h = getattr(self, "_h", None)
        if h is not None:
            self._lib.rbss_free(h)
            self._h = None

    def _invoke(self, fn, *args):
        """fn(handle, *args) under the robot's lock; a failure raised with its message."""
        with self._lock:
            code = fn(self._h, *args)
            if code != 0:
                raise RbssError(code, self._lib.rbss_last_error(self._h).decode())

    def _call(self, name, *args):
        self._invoke(getattr(self._lib, name), *args)

    @staticmethod
    def _arr(v, length, what):
        a = np.ascontiguousarray(v, dtype=np.float64)
        if a.ndim not in (1, 2) or a.shape[-1] != length:
            raise ValueError(f"{what}: expected shape ({length},) or (k, {length}), got {a.shape}")
        return a

    @staticmethod
    def _shared(v, length, what):
        """An optional input given once for every row (x_start, simulate's u): its address."""
        if v is None:
            return None
        a = np.ascontiguousarray(v, dtype=np.float64)
        if a.shape != (length,):
            raise ValueError(f"{what}: expected shape ({length},), got {a.shape}")
        return a

    @staticmethod
    def _outs(out, shapes, inputs=()):
        """The output arrays: new, or `out` (one array, or a tuple for several) checked:
        writable, and sharing no memory with the inputs or each other."""
        if out is None:
            return [np.empty(s) for s in shapes]
        given = [out] if len(shapes) == 1 else out
        if len(shapes) > 1 and (not isinstance(out, tuple) or len(out) != len(shapes)):
            raise ValueError(f"out: expected a tuple of {len(shapes)} arrays")
        for a, s in zip(given, shapes):
            if not (
                type(a) is np.ndarray
                and a.dtype == np.float64
                and a.shape == s
                and a.flags.c_contiguous
                and a.flags.writeable
            ):
                raise ValueError(f"out: expected a writable C-contiguous float64 array of shape {s}")
        others = [a for a in inputs if a is not None]
        for a in given:
            if any(np.may_share_memory(a, b) for b in others):
                raise ValueError("out: shares memory with an input or another output")
            others.append(a)
        return list(given)

    def _rows(self, fn, inputs, out_lengths, out=None, shared=()):
        """Calls fn(rows..., outs...) per row of the inputs (1-D: one call); `shared`: the
        inputs given once for every row."""
        batched = inputs[0].ndim == 2
        k = inputs[0].shape[0] if batched else 1
        for a in inputs:
            if (a.ndim == 2) != batched or (batched and a.shape[0] != k):
                raise ValueError("batched inputs need the same number of rows")
        outs = self._outs(out, [(k, n) if batched else (n,) for n in out_lengths], [*inputs, *shared])
        for i in range(k):
            rows = [a[i] if batched else a for a in inputs]
            fn(*rows, *[o[i] if batched else o for o in outs])
        return outs

    def _vector(self, name, inputs, out_length, out):
        """One result per row of a C function f(h, inputs..., out)."""
        f = getattr(self._lib, name)

        def one(*a):
            self._invoke(f, *[_ptr(v) for v in a])

        return self._rows(one, inputs, [out_length], out)[0]

    # ---- kinematics ----

    def ik(self, pose, x_start=None, out=None):
        """Every coordinate from the outputs (shape (outputs,) or (k, outputs)); each row
        starts from x_start (default: the home)."""
        pose = self._arr(pose, self.outputs, "pose")
        start = self._shared(x_start, self.n, "x_start")
        s = None if start is None else _ptr(start)

        def one(p, x):
            self._call("rbss_ik", _ptr(p), s, _ptr(x))

        return self._rows(one, [pose], [self.n], out, [start])[0]

    def fk(self, q, x_start=None, out=None):
        """Every coordinate from the actuated ones."""
        q = self._arr(q, self.actuated, "q")
        start = self._shared(x_start, self.n, "x_start")
        s = None if start is None else _ptr(start)

        def one(qi, x):
            self._call("rbss_fk", _ptr(qi), s, _ptr(x))

        return self._rows(one, [q], [self.n], out, [start])[0]

    def velocity(self, x, pose_dot, out=None):
        """Xdot from the output rates at x (inverse velocity)."""
        ins = [self._arr(x, self.n, "x"), self._arr(pose_dot, self.outputs, "pose_dot")]
        return self._vector("rbss_inverse_velocity", ins, self.n, out)

    def forward_velocity(self, x, qdot, out=None):
        """Xdot from the actuated rates at x."""
        ins = [self._arr(x, self.n, "x"), self._arr(qdot, self.actuated, "qdot")]
        return self._vector("rbss_forward_velocity", ins, self.n, out)

    def acceleration(self, x, xdot, pose_ddot, out=None):
        """Xddot from the output accelerations at (x, xdot)."""
        ins = [
            self._arr(x, self.n, "x"),
            self._arr(xdot, self.n, "xdot"),
            self._arr(pose_ddot, self.outputs, "pose_ddot"),
        ]
        return self._vector("rbss_inverse_acceleration", ins, self.n, out)

    def forward_acceleration(self, x, xdot, qddot, out=None):
        """Xddot from the actuated accelerations at (x, xdot)."""
        ins = [
            self._arr(x, self.n, "x"),
            self._arr(xdot, self.n, "xdot"),
            self._arr(qddot, self.actuated, "qddot"),
        ]
        return self._vector("rbss_forward_acceleration", ins, self.n, out)

    # ---- dynamics ----

    def inverse_dynamics(self, x, xdot, xddot, out=None):
        """(U, lambda) for the motion (x, xdot, xddot)."""
        arrs = [self._arr(x, self.n, "x"), self._arr(xdot, self.n, "xdot"), self._arr(xddot, self.n, "xddot")]
        return tuple(
            self._rows(
                lambda a, b, c, u, lam: self._call(
                    "rbss_inverse_dynamics", _ptr(a), _ptr(b), _ptr(c), _ptr(u), _ptr(lam)
                ),
                arrs,
                [self.actuated, self.m],
                out,
            )
        )

    def forward_dynamics(self, x, xdot, u, out=None):
        """(Xddot, lambda) under the actuated forces u; (k, n) inputs loop in the library.
        `out`: a tuple (xddot, lambda) of arrays to write."""
        if out is None and _plain(x, self.n) and _plain(xdot, self.n) and _plain(u, self.actuated):
            # The common case first, with the fewest Python operations (the per-call cost).
            xddot = np.empty(self.n)
            lam = np.empty(self.m)
            self._invoke(self._fd, _ptr(x), _ptr(xdot), _ptr(u), _ptr(xddot), _ptr(lam))
            return xddot, lam
        x = self._arr(x, self.n, "x")
        xdot = self._arr(xdot, self.n, "xdot")
        u = self._arr(u, self.actuated, "u")
        batched = x.ndim == 2
        k = x.shape[0] if batched else 1
        if any((a.ndim == 2) != batched or (batched and a.shape[0] != k) for a in (xdot, u)):
            raise ValueError("batched inputs need the same number of rows")
        shapes = [(k, self.n), (k, self.m)] if batched else [(self.n,), (self.m,)]
        xddot, lam = self._outs(out, shapes, [x, xdot, u])
        ptrs = [_ptr(a) for a in (x, xdot, u, xddot, lam)]
        if batched:
            self._call("rbss_forward_dynamics_batch", k, *ptrs)
        else:
            self._call("rbss_forward_dynamics", *ptrs)
        return xddot, lam

    def simulate(
        self,
        x0,
        xdot0,
        t_end,
        u=None,
        rtol=1e-10,
        atol=1e-12,
        out=None,
        method="dopri5",
        state_tol=1e-6,
        project=False,
        full_output=False,
    ):
        """(x, xdot) at t_end from (x0, xdot0) at 0 under constant forces u (default zero);
        (k, n) initial states are simulated one after the other. method: "dopri5" or "dop853"
        (Dormand-Prince 8(5,3): fewer steps at tight tolerances). An initial state with
        max |f(x0)| or max |G xdot0| above state_tol is an RbssError (code RBSS_ERR_STATE, the
        residual in the message) unless project=True, which projects it onto the constraints.
        full_output=True also returns [max |f(x0)|, max |G xdot0|, max |dX|, max |dXdot|] (per
        row): the residuals and how far the projection moved the state (rbss_simulate_checked)."""
        code = _method_code(method)
        ins = [self._arr(x0, self.n, "x0"), self._arr(xdot0, self.n, "xdot0")]
        ua = self._shared(u, self.actuated, "u")
        up = None if ua is None else _ptr(ua)
        if out is not None and not (isinstance(out, tuple) and len(out) == 2):
            raise ValueError("out: expected a tuple of 2 arrays")
        # The check's numbers: a third output, made here (`out` gives the first two).
        state = np.zeros((ins[0].shape[0], 4) if ins[0].ndim == 2 else (4,))
        proj = 1 if project else 0

        def one(a, b, x, xdot, s):
            self._call(
                "rbss_simulate_checked",
                code,
                _ptr(a),
                _ptr(b),
                up,
                t_end,
                rtol,
                atol,
                state_tol,
                proj,
                _ptr(x),
                _ptr(xdot),
                _ptr(s),
            )

        given = None if out is None else (*out, state)
        x, xdot, state = self._rows(one, ins, [self.n, self.n, 4], given, [ua])
        if out is not None:
            x, xdot = out
        return (x, xdot, state) if full_output else (x, xdot)

    def roundtrip(self, x, xdot, xddot):
        """The paper's round trip at a state: inverse dynamics, then forward dynamics under its
        forces; returns max |Xddot_forward - xddot| (rounding when the state is consistent)."""
        return _roundtrip(self, x, xdot, xddot)

    def energy(self, x, xdot, out=None):
        """[T, Pi]."""
        ins = [self._arr(x, self.n, "x"), self._arr(xdot, self.n, "xdot")]
        return self._vector("rbss_energy", ins, 2, out)

    # ---- kernels ----

    def constraints(self, x, out=None):
        """f(X) (m values)."""
        return self._vector("rbss_constraints", [self._arr(x, self.n, "x")], self.m, out)

    def _matrix(self, name, x, rows, cols):
        """A column-major (rows x cols) kernel as numpy's (rows, cols) (or (k, rows, cols))."""
        flat = self._vector(name, [self._arr(x, self.n, "x")], rows * cols, None)
        return np.swapaxes(flat.reshape(flat.shape[:-1] + (cols, rows)), -1, -2)

    def jacobian(self, x):
        """G = df/dX, shape (m, n) (or (k, m, n))."""
        return self._matrix("rbss_jacobian", x, self.m, self.n)

    def gamma(self, x, xdot, out=None):
        """gamma = -(dG/dt) Xdot (m values)."""
        ins = [self._arr(x, self.n, "x"), self._arr(xdot, self.n, "xdot")]
        return self._vector("rbss_gamma", ins, self.m, out)

    def mass_matrix(self, x):
        """M(X), shape (n, n) (or (k, n, n))."""
        return self._matrix("rbss_mass_matrix", x, self.n, self.n)

    def psi(self, x, xdot, out=None):
        """psi(X, Xdot) (n values)."""
        ins = [self._arr(x, self.n, "x"), self._arr(xdot, self.n, "xdot")]
        return self._vector("rbss_psi", ins, self.n, out)

    # ---- derivatives ----

    def _shaped_rows(self, fn, ins, shapes):
        """fn(rows..., outs...) per row; the outputs of the (rows, cols) `shapes` shaped."""
        lengths = [r * (1 if c is None else c) for r, c in shapes]
        outs = self._rows(fn, ins, lengths)
        return [_shaped(o, r, c) for o, (r, c) in zip(outs, shapes)]

    def forward_dynamics_derivatives(self, x, xdot, u):
        """Forward dynamics at (x, xdot, u) and its derivatives (rbss_forward_dynamics_derivatives):
        a dict of "xddot" (n,), "lambda" (m,), "dxddot_dx", "dxddot_dxdot" (n, n), "dxddot_du"
        (n, actuated), "dlambda_dx", "dlambda_dxdot" (m, n), "dlambda_du" (m, actuated); (k, n)
        inputs give each a leading axis k."""
        n, m, a = self.n, self.m, self.actuated
        ins = [self._arr(x, n, "x"), self._arr(xdot, n, "xdot"), self._arr(u, a, "u")]
        shapes = [(n, None), (m, None), (n, n), (n, n), (n, a), (m, n), (m, n), (m, a)]
        f = self._lib.rbss_forward_dynamics_derivatives

        def one(*arrays):
            self._invoke(f, *[_ptr(v) for v in arrays])

        return dict(zip(_FD_DERIVATIVES, self._shaped_rows(one, ins, shapes)))

    def inverse_dynamics_derivatives(self, x, xdot, xddot):
        """Inverse dynamics at the motion (x, xdot, xddot) and its derivatives
        (rbss_inverse_dynamics_derivatives): a dict of "u" (actuated,), "lambda" (m,), "du_dx",
        "du_dxdot", "du_dxddot" (actuated, n), "dlambda_dx", "dlambda_dxdot", "dlambda_dxddot"
        (m, n); (k, n) inputs give each a leading axis k."""
        n, m, a = self.n, self.m, self.actuated
        ins = [self._arr(x, n, "x"), self._arr(xdot, n, "xdot"), self._arr(xddot, n, "xddot")]
        shapes = [(a, None), (m, None), (a, n), (a, n), (a, n), (m, n), (m, n), (m, n)]
        f = self._lib.rbss_inverse_dynamics_derivatives

        def one(*arrays):
            self._invoke(f, *[_ptr(v) for v in arrays])

        return dict(zip(_ID_DERIVATIVES, self._shaped_rows(one, ins, shapes)))

    def linearize(self, x, xdot, u, coordinates="outputs"):
        """(A, B) of d/dt [y; ydot] = A [y; ydot] + B U, forward dynamics linearised on the
        constraint manifold at (x, xdot, u) (rbss_linearize) in the d = n - m independent
        coordinates y: "outputs" (output_index's) or "actuated" (actuated_index's, fully
        actuated robots). A (2d, 2d), B (2d, actuated); (k, n) inputs give (k, 2d, 2d) and
        (k, 2d, actuated). A state off the manifold (max |f(x)| or max |G xdot| above 1e-6) is
        an RbssError with code RBSS_ERR_STATE."""
        code = _code(_COORDINATES, coordinates, "coordinates")
        n, a = self.n, self.actuated
        w = 2 * (n - self.m)
        ins = [self._arr(x, n, "x"), self._arr(xdot, n, "xdot"), self._arr(u, a, "u")]
        f = self._lib.rbss_linearize

        def one(xi, vi, ui, am, bm):
            self._invoke(f, code, _ptr(xi), _ptr(vi), _ptr(ui), _ptr(am), _ptr(bm))

        return tuple(self._shaped_rows(one, ins, [(w, w), (w, a)]))

    def step_derivatives(self, x, xdot, u, h, method="rk4", baumgarte=None):
        """One step of h > 0 from the state s = (x, xdot) with u held over it, and its
        Jacobians (rbss_step_derivatives): (x_next, xdot_next, F_x, F_u), F_x = ds'/ds
        (2n, 2n; s = (X, Xdot) in that order), F_u = ds'/dU (2n, actuated). method: "rk4" or
        "semi_implicit_euler"; baumgarte: [alpha, beta] gains on each stage's acceleration
        (default none). (k, n) inputs give each result a leading axis k."""
        code = _code(_STEPS, method, "method")
        n, a = self.n, self.actuated
        ins = [self._arr(x, n, "x"), self._arr(xdot, n, "xdot"), self._arr(u, a, "u")]
        gains = self._shared(baumgarte, 2, "baumgarte")
        g = None if gains is None else _ptr(gains)
        f = self._lib.rbss_step_derivatives
        dt = float(h)

        def one(xi, vi, ui, x1, v1, fx, fu):
            self._invoke(f, code, _ptr(xi), _ptr(vi), _ptr(ui), dt, g, _ptr(x1), _ptr(v1), _ptr(fx), _ptr(fu))

        return tuple(self._shaped_rows(one, ins, [(n, None), (n, None), (2 * n, 2 * n), (2 * n, a)]))
