"""rbss from Python: a robot compiled from its model file, called through its C ABI.

    import rbss
    robot = rbss.compile("models/stewart_6ups.toml")   # generated, compiled, cached (rbss library)
    x = robot.ik([0.1, 0, 0.94, 0.1, 0, 0])             # numpy arrays in and out
    xddot, lam = robot.forward_dynamics(x, np.zeros(robot.n), np.zeros(robot.actuated))

A thin layer (ctypes + numpy) over the library's C ABI (ffi/include/rbss.h, version 1): every
method checks shapes, calls the library and raises RbssError with rbss's message on a failure.
Batched inputs of shape (k, n) are accepted by every method; forward_dynamics loops over them
in the library (rbss_forward_dynamics_batch), the others call it once per row.
"""

import ctypes
import os
import shutil
import subprocess

import numpy as np

__all__ = ["RbssError", "Robot", "compile", "ABI_VERSION"]

ABI_VERSION = 1

# Arrays go as addresses (c_void_p): cheaper per call than ctypes pointer objects.
_D = ctypes.c_void_p
_H = ctypes.c_void_p
_INT = ctypes.c_int
_SIZE = ctypes.c_size_t

# name: (argument types after the handle)
_SIGNATURES = {
    "rbss_home": [_D],
    "rbss_ik": [_D, _D, _D],
    "rbss_fk": [_D, _D, _D],
    "rbss_inverse_velocity": [_D, _D, _D],
    "rbss_forward_velocity": [_D, _D, _D],
    "rbss_inverse_acceleration": [_D, _D, _D, _D],
    "rbss_forward_acceleration": [_D, _D, _D, _D],
    "rbss_inverse_dynamics": [_D, _D, _D, _D, _D],
    "rbss_forward_dynamics": [_D, _D, _D, _D, _D],
    "rbss_forward_dynamics_batch": [_SIZE, _D, _D, _D, _D, _D],
    "rbss_simulate": [_D, _D, _D, ctypes.c_double, ctypes.c_double, ctypes.c_double, _D, _D],
    "rbss_energy": [_D, _D, _D],
    "rbss_constraints": [_D, _D],
    "rbss_jacobian": [_D, _D],
    "rbss_gamma": [_D, _D, _D],
    "rbss_mass_matrix": [_D, _D],
    "rbss_psi": [_D, _D, _D],
}


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


def compile(model_file):
    """The robot of `model_file`, compiled into a library (cached as `rbss --model-file` does)."""
    out = subprocess.run(
        [_rbss_command(), "library", "--model-file", os.fspath(model_file)],
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:
        raise RbssError(-1, out.stderr.strip())
    return Robot(out.stdout.strip())


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
    """A robot's library, loaded: sizes and names as attributes, solvers as methods."""

    def __init__(self, library_path):
        self.library_path = library_path
        lib = ctypes.CDLL(library_path)
        lib.rbss_abi_version.restype = ctypes.c_uint32
        if lib.rbss_abi_version() != ABI_VERSION:
            raise RbssError(-1, f"{library_path}: C ABI {lib.rbss_abi_version()}, expected {ABI_VERSION}")
        lib.rbss_new.restype = _H
        lib.rbss_free.argtypes = [_H]
        lib.rbss_last_error.argtypes = [_H]
        lib.rbss_last_error.restype = ctypes.c_char_p
        lib.rbss_size.argtypes = [_H, _INT]
        lib.rbss_size.restype = _SIZE
        for f in ("rbss_name",):
            getattr(lib, f).argtypes = [_H]
            getattr(lib, f).restype = ctypes.c_char_p
        for f in ("rbss_coordinate", "rbss_constraint"):
            getattr(lib, f).argtypes = [_H, _SIZE]
            getattr(lib, f).restype = ctypes.c_char_p
        for f in ("rbss_actuated", "rbss_output"):
            getattr(lib, f).argtypes = [_H, _SIZE]
            getattr(lib, f).restype = _SIZE
        for name, args in _SIGNATURES.items():
            fn = getattr(lib, name)
            fn.argtypes = [_H] + args
            fn.restype = _INT
        self._lib = lib
        h = lib.rbss_new()
        if not h:
            raise RbssError(-1, lib.rbss_last_error(None).decode())
        self._h = _H(h)
        self.n, self.m, self.actuated, self.outputs = (lib.rbss_size(self._h, i) for i in range(4))
        self.has_dynamics = bool(lib.rbss_size(self._h, 4))
        self.name = lib.rbss_name(self._h).decode()
        self.coordinates = [lib.rbss_coordinate(self._h, i).decode() for i in range(self.n)]
        self.constraint_names = [lib.rbss_constraint(self._h, i).decode() for i in range(self.m)]
        self.actuated_index = [lib.rbss_actuated(self._h, i) for i in range(self.actuated)]
        self.output_index = [lib.rbss_output(self._h, i) for i in range(self.outputs)]
        self.home = np.empty(self.n)
        self._call("rbss_home", _ptr(self.home))
        # The bound functions, looked up once (the per-call cost is the call itself).
        self._fd = lib.rbss_forward_dynamics

    def __del__(self):
        h = getattr(self, "_h", None)
        if h is not None:
            self._lib.rbss_free(h)
            self._h = None

    def _call(self, name, *args):
        code = getattr(self._lib, name)(self._h, *args)
        if code != 0:
            raise RbssError(code, self._lib.rbss_last_error(self._h).decode())

    def _check(self, code):
        if code != 0:
            raise RbssError(code, self._lib.rbss_last_error(self._h).decode())

    @staticmethod
    def _arr(v, length, what):
        a = np.ascontiguousarray(v, dtype=np.float64)
        if a.ndim not in (1, 2) or a.shape[-1] != length:
            raise ValueError(f"{what}: expected shape ({length},) or (k, {length}), got {a.shape}")
        return a

    def _rows(self, fn, inputs, out_lengths):
        """Calls fn(rows..., outs...) per row of the inputs (1-D: one call)."""
        batched = inputs[0].ndim == 2
        k = inputs[0].shape[0] if batched else 1
        for a in inputs:
            if (a.ndim == 2) != batched or (batched and a.shape[0] != k):
                raise ValueError("batched inputs need the same number of rows")
        outs = [np.empty((k, length)) for length in out_lengths]
        for i in range(k):
            rows = [a[i] if batched else a for a in inputs]
            fn(*rows, *[o[i] for o in outs])
        return [o if batched else o[0] for o in outs]

    # ---- kinematics ----

    def ik(self, pose, x_start=None):
        """Every coordinate from the outputs (shape (outputs,) or (k, outputs)); each row
        starts from x_start (default: the home)."""
        pose = self._arr(pose, self.outputs, "pose")
        start = None if x_start is None else _ptr(self._arr(x_start, self.n, "x_start"))

        def one(p, x):
            self._call("rbss_ik", _ptr(p), start, _ptr(x))

        return self._rows(one, [pose], [self.n])[0]

    def fk(self, q, x_start=None):
        """Every coordinate from the actuated ones."""
        q = self._arr(q, self.actuated, "q")
        start = None if x_start is None else _ptr(self._arr(x_start, self.n, "x_start"))

        def one(qi, x):
            self._call("rbss_fk", _ptr(qi), start, _ptr(x))

        return self._rows(one, [q], [self.n])[0]

    def velocity(self, x, pose_dot):
        """Xdot from the output rates at x (inverse velocity)."""
        x = self._arr(x, self.n, "x")
        v = self._arr(pose_dot, self.outputs, "pose_dot")
        return self._rows(
            lambda a, b, o: self._call("rbss_inverse_velocity", _ptr(a), _ptr(b), _ptr(o)),
            [x, v],
            [self.n],
        )[0]

    def forward_velocity(self, x, qdot):
        x = self._arr(x, self.n, "x")
        v = self._arr(qdot, self.actuated, "qdot")
        return self._rows(
            lambda a, b, o: self._call("rbss_forward_velocity", _ptr(a), _ptr(b), _ptr(o)),
            [x, v],
            [self.n],
        )[0]

    # ---- dynamics ----

    def inverse_dynamics(self, x, xdot, xddot):
        """(U, lambda) for the motion (x, xdot, xddot)."""
        arrs = [self._arr(x, self.n, "x"), self._arr(xdot, self.n, "xdot"), self._arr(xddot, self.n, "xddot")]
        return tuple(
            self._rows(
                lambda a, b, c, u, lam: self._call(
                    "rbss_inverse_dynamics", _ptr(a), _ptr(b), _ptr(c), _ptr(u), _ptr(lam)
                ),
                arrs,
                [self.actuated, self.m],
            )
        )

    def forward_dynamics(self, x, xdot, u):
        """(Xddot, lambda) under the actuated forces u; (k, n) inputs loop in the library."""
        if _plain(x, self.n) and _plain(xdot, self.n) and _plain(u, self.actuated):
            # The common case first, with the fewest Python operations (the per-call cost).
            xddot = np.empty(self.n)
            lam = np.empty(self.m)
            self._check(self._fd(self._h, _ptr(x), _ptr(xdot), _ptr(u), _ptr(xddot), _ptr(lam)))
            return xddot, lam
        x = self._arr(x, self.n, "x")
        xdot = self._arr(xdot, self.n, "xdot")
        u = self._arr(u, self.actuated, "u")
        if x.ndim == 1 and xdot.ndim == 1 and u.ndim == 1:
            return self.forward_dynamics(x, xdot, u)
        if not (x.ndim == xdot.ndim == u.ndim == 2 and x.shape[0] == xdot.shape[0] == u.shape[0]):
            raise ValueError("batched inputs need the same number of rows")
        k = x.shape[0]
        xddot = np.empty((k, self.n))
        lam = np.empty((k, self.m))
        self._call("rbss_forward_dynamics_batch", k, _ptr(x), _ptr(xdot), _ptr(u), _ptr(xddot), _ptr(lam))
        return xddot, lam

    def simulate(self, x0, xdot0, t_end, u=None, rtol=1e-10, atol=1e-12):
        """(x, xdot) at t_end from (x0, xdot0) at 0 under constant forces u (default zero)."""
        x0 = self._arr(x0, self.n, "x0")
        xdot0 = self._arr(xdot0, self.n, "xdot0")
        up = None if u is None else _ptr(self._arr(u, self.actuated, "u"))
        x = np.empty(self.n)
        xdot = np.empty(self.n)
        self._call("rbss_simulate", _ptr(x0), _ptr(xdot0), up, t_end, rtol, atol, _ptr(x), _ptr(xdot))
        return x, xdot

    def roundtrip(self, x, xdot, xddot):
        """The paper's round trip at a state: inverse dynamics, then forward dynamics under its
        forces; returns max |Xddot_forward - xddot| (rounding when the state is consistent)."""
        u, _ = self.inverse_dynamics(x, xdot, xddot)
        back, _ = self.forward_dynamics(x, xdot, u)
        return float(np.max(np.abs(back - np.asarray(xddot))))

    def energy(self, x, xdot):
        """[T, Pi]."""
        arrs = [self._arr(x, self.n, "x"), self._arr(xdot, self.n, "xdot")]
        return self._rows(
            lambda a, b, o: self._call("rbss_energy", _ptr(a), _ptr(b), _ptr(o)), arrs, [2]
        )[0]

    # ---- kernels ----

    def constraints(self, x):
        """f(X) (m values)."""
        x = self._arr(x, self.n, "x")
        return self._rows(lambda a, o: self._call("rbss_constraints", _ptr(a), _ptr(o)), [x], [self.m])[0]

    def jacobian(self, x):
        """G = df/dX, shape (m, n) (or (k, m, n))."""
        x = self._arr(x, self.n, "x")
        g = self._rows(lambda a, o: self._call("rbss_jacobian", _ptr(a), _ptr(o)), [x], [self.m * self.n])[0]
        # Column-major in the library: column j at j m.
        return np.swapaxes(g.reshape(g.shape[:-1] + (self.n, self.m)), -1, -2)

    def gamma(self, x, xdot):
        arrs = [self._arr(x, self.n, "x"), self._arr(xdot, self.n, "xdot")]
        return self._rows(lambda a, b, o: self._call("rbss_gamma", _ptr(a), _ptr(b), _ptr(o)), arrs, [self.m])[0]

    def mass_matrix(self, x):
        x = self._arr(x, self.n, "x")
        mm = self._rows(lambda a, o: self._call("rbss_mass_matrix", _ptr(a), _ptr(o)), [x], [self.n * self.n])[0]
        return np.swapaxes(mm.reshape(mm.shape[:-1] + (self.n, self.n)), -1, -2)

    def psi(self, x, xdot):
        arrs = [self._arr(x, self.n, "x"), self._arr(xdot, self.n, "xdot")]
        return self._rows(lambda a, b, o: self._call("rbss_psi", _ptr(a), _ptr(b), _ptr(o)), arrs, [self.n])[0]
