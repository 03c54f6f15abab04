"""One robot shared by two threads (issue 37). rbss.h allows one call at a time on a handle; the
ctypes layer releases the GIL during a call, so without its lock two calls ran on one handle at
once (wrong rows with exit 0, and aborts on a double free). Each implementation: 20 runs of two
threads calling one robot (batched inverse kinematics, forward dynamics, and a refused input
whose error message must be its own), compared bit for bit with the results of one thread. The
runs are in a child process, so that an abort is counted rather than ending pytest.
"""

import os
import subprocess
import sys

import pytest

import rbss

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MODEL = os.path.join(ROOT, "models", "stewart_6ups.toml")
RUNS = 20

SCRIPT = r"""
import sys, threading
import numpy as np
import rbss

backend, model, runs = sys.argv[1], sys.argv[2], int(sys.argv[3])
robot = rbss.compile(model, backend=backend)
rng = np.random.default_rng(5)
home = robot.home[robot.output_index]
work = []
for t in range(2):
    poses = home + rng.uniform(-0.02, 0.02, (8, robot.outputs))
    xs = robot.ik(poses)
    xdots = np.stack([robot.velocity(x, rng.uniform(-0.1, 0.1, robot.outputs)) for x in xs])
    us = rng.uniform(-300, 300, (8, robot.actuated))
    ref = [robot.forward_dynamics(x, v, u) for x, v, u in zip(xs, xdots, us)]
    work.append((poses, xs, xdots, us, ref))
bad = home.copy()
bad[0] = np.nan
for run in range(runs):
    wrong, errors = [0, 0], []
    barrier = threading.Barrier(2)

    def worker(t):
        poses, xs, xdots, us, ref = work[t]
        barrier.wait()
        try:
            for _ in range(30):
                got = robot.ik(poses)
                wrong[t] += int(np.sum(np.any(got != xs, axis=1)))
                for i in range(len(xs)):
                    a, b = robot.forward_dynamics(xs[i], xdots[i], us[i])
                    wrong[t] += int(not (np.array_equal(a, ref[i][0]) and np.array_equal(b, ref[i][1])))
                try:
                    robot.ik(bad)
                    wrong[t] += 1
                except rbss.RbssError as e:
                    wrong[t] += int(e.code != 2 or "`pose`[0] is not finite" not in e.message)
        except Exception as e:  # anything else (a borrow error, a foreign message) is counted
            errors.append(repr(e))

    threads = [threading.Thread(target=worker, args=(t,)) for t in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    print(f"run {run} wrong {sum(wrong)} errors {len(errors)} {errors[:1]}", flush=True)
"""


@pytest.mark.parametrize("backend", ["native", "ctypes"])
def test_one_robot_two_threads(backend):
    if backend == "native" and not rbss.native_available():
        if os.environ.get("RBSS_REQUIRE_NATIVE") == "1":
            pytest.fail("rbss._native is not importable (RBSS_REQUIRE_NATIVE=1)")
        pytest.skip("rbss._native is not installed")
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, backend, MODEL, str(RUNS)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    runs = [line.split() for line in out.stdout.splitlines() if line.startswith("run ")]
    wrong = sum(1 for r in runs if r[3] != "0")
    failed = sum(1 for r in runs if r[5] != "0")
    summary = (
        f"{backend}: {len(runs)} of {RUNS} runs finished, exit {out.returncode}, {wrong} with wrong "
        f"results, {failed} with errors\n{out.stdout[-2000:]}{out.stderr[-2000:]}"
    )
    assert out.returncode == 0 and len(runs) == RUNS and wrong == 0 and failed == 0, summary
