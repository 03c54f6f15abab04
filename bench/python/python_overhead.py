"""Python's overhead on the 6-UPS's forward dynamics (issues 22, 37), against the same calls from C.

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install ./python      # as a user installs it
    RBSS=target/release/rbss /tmp/venv/bin/python bench/python/python_overhead.py

(rbss._native measured when it is installed; with PYTHONPATH=python and no build, the ctypes
layer alone. It replaced the probe bench/python/pyo3_probe, one robot compiled into a PyO3
extension, which measured 0.48 to 0.50 us over: BENCHMARKS.md.)

Prints ns per call (medians), for both implementations of the package (rbss._native, PyO3,
when it is installed; the ctypes layer, with its per-robot lock): the C loop of
rbss_forward_dynamics (fd_loop.c: the Rust call), robot.forward_dynamics on one state (new
arrays, and into preallocated `out` arrays), the bare ctypes call (arrays made beforehand, no
lock), and robot.forward_dynamics on 1000 states at once (rbss_forward_dynamics_batch), per state.
With `--cpu`, every time is the thread's CPU time (Python's time.thread_time, the C loop's
CLOCK_THREAD_CPUTIME_ID) rather than the wall clock: on a loaded machine the wall clock counts
the other processes' slices.
"""

import os
import subprocess
import sys
import tempfile
import time

import numpy as np

import rbss

ROUNDS = 5
CPU = "--cpu" in sys.argv[1:]
CLOCK = time.thread_time if CPU else time.perf_counter
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def median_ns(f, calls, passes=21):
    times = []
    for _ in range(passes):
        t0 = CLOCK()
        for _ in range(calls):
            f()
        times.append((CLOCK() - t0) / calls)
    return 1e9 * float(np.median(times))


def main():
    robot = rbss.compile(os.path.join(ROOT, "models", "stewart_6ups.toml"), backend="ctypes")
    rng = np.random.default_rng(7)
    k = 1000
    home_pose = robot.home[robot.output_index]
    poses = home_pose + rng.uniform(-0.02, 0.02, (k, 6))
    xs = robot.ik(poses)
    xdots = np.stack([robot.velocity(x, rng.uniform(-0.1, 0.1, 6)) for x in xs])
    us = rng.uniform(-500, 500, (k, 6))

    x, xdot, u = xs[0], xdots[0], us[0]
    robots = [robot]
    if rbss.native_available():
        robots.insert(0, rbss.compile(os.path.join(ROOT, "models", "stewart_6ups.toml"), backend="native"))
    else:
        print("rbss._native: not installed (pip install ./python)")
    for r in robots:
        a, b = r.forward_dynamics(x, xdot, u)
        c, d = robot.forward_dynamics(x, xdot, u)
        assert np.array_equal(a, c) and np.array_equal(b, d), "the implementations differ"

    # Rounds of every measurement, the C loop in each: on a shared machine the load moves
    # between rounds, so each overhead is taken against its own round's C loop; printed: the
    # median over the rounds, and their range.
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        states = os.path.join(tmp, "states.bin")
        np.hstack([xs, xdots, us]).astype(np.float64).tofile(states)
        exe = os.path.join(tmp, "fd_loop")
        lib = os.path.dirname(robot.library_path)
        subprocess.run(
            ["cc", "-O2", "-I", os.path.join(ROOT, "ffi", "include"),
             os.path.join(ROOT, "bench", "python", "fd_loop.c"), lib_flag(robot.library_path),
             "-Wl,-rpath," + lib, "-o", exe],
            check=True,
        )
        for _ in range(ROUNDS):
            c_ns = float(subprocess.run([exe, states, str(k)] + (["cpu"] if CPU else []), check=True,
                                        capture_output=True, text=True).stdout)
            rows.setdefault("C loop (the Rust call), ns/call", []).append((c_ns, None))
            for r in robots:
                tag = r.backend
                out = (np.empty(r.n), np.empty(r.m))
                outs = (np.empty((k, r.n)), np.empty((k, r.m)))
                single = median_ns(lambda: r.forward_dynamics(x, xdot, u), 2000)
                into = median_ns(lambda: r.forward_dynamics(x, xdot, u, out=out), 2000)
                batch = median_ns(lambda: r.forward_dynamics(xs, xdots, us), 1) / k
                batch_out = median_ns(lambda: r.forward_dynamics(xs, xdots, us, out=outs), 1) / k
                rows.setdefault(f"{tag} one state, ns/call (over C)", []).append((single, single - c_ns))
                rows.setdefault(f"{tag} one state out=, ns/call (over C)", []).append((into, into - c_ns))
                rows.setdefault(f"{tag} 1000 batched, ns/state (x C)", []).append((batch, batch / c_ns))
                rows.setdefault(f"{tag} 1000 batched out=, ns/state (x C)", []).append((batch_out, batch_out / c_ns))
            xddot, lam = np.empty(robot.n), np.empty(robot.m)
            args = [robot._h] + [rbss._ptr(a) for a in (x, xdot, u, xddot, lam)]
            fd = robot._fd
            bare = median_ns(lambda: fd(*args), 2000)
            rows.setdefault("ctypes bare call, ns/call (over C)", []).append((bare, bare - c_ns))
    print(f"rbss from {os.path.dirname(rbss.__file__)}; {'thread CPU time' if CPU else 'wall clock'}")
    for name, vals in rows.items():
        v = np.array([a for a, _ in vals])
        line = f"{name:40} {np.median(v):8.1f}"
        rel = [b for _, b in vals if b is not None]
        if rel:
            fmt = ".3f" if "x C" in name else ".0f"
            line += f"   ({np.median(rel):{fmt}}; {min(rel):{fmt}} to {max(rel):{fmt}})"
        print(line)


def lib_flag(path):
    # The cache's library has no lib*.so name to link by -l: link the file itself.
    return path


if __name__ == "__main__":
    sys.exit(main())
