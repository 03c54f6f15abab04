"""The Python layer on the 6-UPS (rbss.compile of models/stewart_6ups.toml, the cache of
`rbss --model-file`). Needs RBSS (the rbss command's path) and numpy; CI runs it in a venv.
Every test runs on both implementations: rbss._native (PyO3; skipped when it is not built,
unless RBSS_REQUIRE_NATIVE=1, as in CI) and the ctypes layer.

The checks are the equations themselves: the IK solution closes the loops, the velocity is in
the kernel of G, inverse then forward dynamics gives the acceleration back, the forward
dynamics satisfies M Xddot = psi + S U - G^T lambda and G Xddot = gamma, the batch equals the
single calls, and errors carry rbss's messages.
"""

import os
import re

import numpy as np
import pytest

import rbss

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


MODEL = os.path.join(ROOT, "models", "stewart_6ups.toml")


@pytest.fixture(scope="module", params=["native", "ctypes"])
def robot(request):
    if request.param == "native" and not rbss.native_available():
        if os.environ.get("RBSS_REQUIRE_NATIVE") == "1":
            pytest.fail("rbss._native is not importable (RBSS_REQUIRE_NATIVE=1)")
        pytest.skip("rbss._native is not built")
    r = rbss.compile(MODEL, backend=request.param)
    assert r.backend == request.param and f"({request.param}" in repr(r)
    return r


@pytest.fixture(scope="module")
def ctypes_robot():
    return rbss.compile(MODEL, backend="ctypes")


def pose_near_home(robot, d):
    p = robot.home[robot.output_index].copy()
    p[0] += d
    return p


def test_structure(robot):
    assert robot.name == "stewart_6ups"
    assert (robot.n, robot.m, robot.actuated, robot.outputs) == (24, 18, 6, 6)
    assert robot.coordinates[:2] == ["d1", "d2"] and robot.coordinates[-1] == "rotz"
    assert robot.has_dynamics


def test_ik_fk_velocity(robot):
    pose = pose_near_home(robot, 0.02)
    x = robot.ik(pose)
    assert np.max(np.abs(robot.constraints(x))) < 1e-12
    np.testing.assert_array_equal(x[robot.output_index], pose)
    x2 = robot.fk(x[robot.actuated_index])
    np.testing.assert_allclose(x2, x, atol=1e-9)
    xdot = robot.velocity(x, [0.1, 0, 0, 0, 0.2, 0])
    assert np.max(np.abs(robot.jacobian(x) @ xdot)) < 1e-12
    # Batched: rows as single calls.
    poses = np.stack([pose_near_home(robot, d) for d in (0.0, 0.01, 0.02)])
    xs = robot.ik(poses)
    assert xs.shape == (3, 24)
    np.testing.assert_array_equal(xs[2], x)


def test_dynamics_round_trip_and_equations(robot):
    x = robot.ik(pose_near_home(robot, 0.01))
    xdot = robot.velocity(x, [0.05, -0.02, 0.1, 0.0, 0.1, -0.1])
    u0 = np.array([100.0, 200.0, 300.0, 400.0, 500.0, 600.0])
    xddot, lam = robot.forward_dynamics(x, xdot, u0)
    G = robot.jacobian(x)
    M = robot.mass_matrix(x)
    S = np.zeros((24, 6))
    S[robot.actuated_index, range(6)] = 1.0
    motion = M @ xddot - robot.psi(x, xdot) - S @ u0 + G.T @ lam
    assert np.max(np.abs(motion)) < 1e-8 * max(1.0, np.max(np.abs(robot.psi(x, xdot))))
    assert np.max(np.abs(G @ xddot - robot.gamma(x, xdot))) < 1e-9
    u, _ = robot.inverse_dynamics(x, xdot, xddot)
    np.testing.assert_allclose(u, u0, rtol=1e-9)
    assert robot.roundtrip(x, xdot, xddot) < 1e-9
    t, pi = robot.energy(x, xdot)
    assert t > 0 and np.isfinite(pi)


def test_batched_forward_dynamics_is_the_single_calls(robot):
    rng = np.random.default_rng(1)
    x = robot.ik(pose_near_home(robot, 0.0))
    k = 50
    xs = np.repeat(x[None, :], k, axis=0)
    xdots = np.stack([robot.velocity(x, rng.uniform(-0.1, 0.1, 6)) for _ in range(k)])
    us = rng.uniform(-500, 500, (k, 6))
    xddot, lam = robot.forward_dynamics(xs, xdots, us)
    for i in (0, 17, k - 1):
        a, b = robot.forward_dynamics(xs[i], xdots[i], us[i])
        np.testing.assert_array_equal(xddot[i], a)
        np.testing.assert_array_equal(lam[i], b)


def test_simulate_keeps_the_constraints(robot):
    x0 = robot.ik(pose_near_home(robot, 0.0))
    u, _ = robot.inverse_dynamics(x0, np.zeros(24), np.zeros(24))
    x, xdot = robot.simulate(x0, np.zeros(24), 0.1, u=u)
    # Held by its static forces: it stays where it was.
    np.testing.assert_allclose(x, x0, atol=1e-8)
    assert np.max(np.abs(robot.constraints(x))) < 1e-10


def test_simulate_batched_is_the_single_runs(robot):
    x0 = robot.ik(pose_near_home(robot, 0.0))
    x1 = robot.ik(pose_near_home(robot, 0.01))
    xdot1 = robot.velocity(x1, [0.0, 0.0, 0.05, 0.0, 0.0, 0.0])
    xs, xdots = robot.simulate(np.stack([x0, x1]), np.stack([np.zeros(24), xdot1]), 0.05)
    a, b = robot.simulate(x1, xdot1, 0.05)
    np.testing.assert_array_equal(xs[1], a)
    np.testing.assert_array_equal(xdots[1], b)
    assert np.max(np.abs(robot.constraints(xs))) < 1e-10


def test_simulate_dop853_agrees_with_dopri5(robot):
    # A platform pushed off its static forces: both integrators at tight tolerances give the
    # same state, to their tolerance, and DOP853 keeps the constraints as projection makes it.
    x0 = robot.ik(pose_near_home(robot, 0.0))
    u, _ = robot.inverse_dynamics(x0, np.zeros(24), np.zeros(24))
    u = u + 50.0
    a, av = robot.simulate(x0, np.zeros(24), 0.2, u=u, rtol=1e-12, atol=1e-14)
    b, bv = robot.simulate(x0, np.zeros(24), 0.2, u=u, rtol=1e-12, atol=1e-14, method="dop853")
    assert np.max(np.abs(a - x0)) > 1e-4  # it moved
    np.testing.assert_allclose(b, a, atol=1e-10)
    np.testing.assert_allclose(bv, av, atol=1e-9)
    assert np.max(np.abs(robot.constraints(b))) < 1e-10
    with pytest.raises(ValueError):
        robot.simulate(x0, np.zeros(24), 0.1, method="rk45")


def _number_after(text, label):
    """The number after `label` in `text`."""
    m = re.search(re.escape(label) + r"\s*([-+0-9.eE]+)", text)
    assert m, f"no {label!r} in {text!r}"
    return float(m.group(1))


def test_simulate_refuses_an_inconsistent_state_or_projects_it_on_request(robot):
    # A leg length 1 cm off its loop: refused (the residual in the message), never moved
    # silently; with project=True projected, and the move reported, equal to the constraint
    # residual's correction (the state ends on the constraints).
    x0 = robot.ik(pose_near_home(robot, 0.0))
    bad = x0.copy()
    bad[0] += 0.01
    f_max = np.max(np.abs(robot.constraints(bad)))
    assert 1e-3 < f_max
    with pytest.raises(rbss.RbssError) as e:
        robot.simulate(bad, np.zeros(24), 0.05)
    assert e.value.code == rbss.RBSS_ERR_STATE == 5
    assert "not consistent with the constraints" in e.value.message
    assert abs(_number_after(e.value.message, "max |f(x0)| =") - f_max) < 1e-3 * f_max
    # The same for a velocity that breaks G xdot = 0.
    xdot = np.zeros(24)
    xdot[0] = 0.1
    gv = np.max(np.abs(robot.jacobian(x0) @ xdot))
    with pytest.raises(rbss.RbssError) as e:
        robot.simulate(x0, xdot, 0.05)
    assert e.value.code == rbss.RBSS_ERR_STATE
    assert abs(_number_after(e.value.message, "max |G xdot0| =") - gv) < 1e-3 * gv
    # project=True: runs, reports [max |f|, max |G xdot|, max |dX|, max |dXdot|].
    x, xd, state = robot.simulate(bad, xdot, 0.05, project=True, full_output=True)
    assert state.shape == (4,)
    assert state[0] == f_max
    assert abs(state[1] - np.max(np.abs(robot.jacobian(bad) @ xdot))) < 1e-12
    assert 1e-3 < state[2] < 0.02 and state[3] > 1e-3, state
    assert np.max(np.abs(robot.constraints(x))) < 1e-10
    # A wide tolerance accepts the state as it is; the run is then the projected one.
    x2, xd2, state2 = robot.simulate(bad, xdot, 0.05, state_tol=1.0, full_output=True)
    np.testing.assert_array_equal(state2, state)
    np.testing.assert_array_equal(x2, x)
    # Batched: the failing row raises; full_output gives one row per state.
    with pytest.raises(rbss.RbssError):
        robot.simulate(np.stack([x0, bad]), np.zeros((2, 24)), 0.05)
    xs, _, states = robot.simulate(np.stack([x0, bad]), np.zeros((2, 24)), 0.05, project=True, full_output=True)
    assert states.shape == (2, 4)
    assert np.all(states[0] < 1e-9) and states[1, 0] == f_max
    # out= still takes the two arrays (the state report is made apart).
    ox, oxd = np.empty(24), np.empty(24)
    got = robot.simulate(x0, np.zeros(24), 0.05, out=(ox, oxd))
    assert got[0] is ox and got[1] is oxd
    with pytest.raises(ValueError):
        robot.simulate(x0, np.zeros(24), 0.05, out=(ox, oxd, np.empty(4)))
    with pytest.raises(rbss.RbssError) as e:
        robot.simulate(x0, np.zeros(24), 0.05, state_tol=0.0)
    assert e.value.code == rbss.RBSS_ERR_ARGUMENT


def test_raw_kernels_refuse_non_finite_outputs(robot):
    # Rates of 1e300: gamma and psi (quadratic in them) overflow; an error, not inf in a
    # success, and the `out` array untouched.
    v = np.full(24, 1e300)
    out = np.full(18, 5.0)
    with pytest.raises(rbss.RbssError) as e:
        robot.gamma(robot.home, v, out=out)
    assert e.value.code == rbss.RBSS_ERR_NONFINITE
    assert "`gamma`[" in e.value.message and "not finite" in e.value.message
    assert np.all(out == 5.0)
    with pytest.raises(rbss.RbssError) as e:
        robot.psi(robot.home, v)
    assert e.value.code == rbss.RBSS_ERR_NONFINITE
    # Finite outputs at the same point of the model: a success.
    assert np.all(np.isfinite(robot.gamma(robot.home, np.ones(24))))


def test_errors_are_exceptions_with_rbss_messages(robot):
    with pytest.raises(rbss.RbssError) as e:
        robot.ik([np.nan, 0, 0.94, 0, 0, 0])
    assert e.value.code == 2
    assert "`pose`[0] is not finite (NaN)" in str(e.value)
    # Every leg of zero length: the platform's Jacobian is singular.
    with pytest.raises(rbss.RbssError) as e:
        robot.fk(np.zeros(6))
    assert e.value.code == 1 and "singular J_p" in str(e.value)
    with pytest.raises(ValueError):
        robot.ik([0.0, 0.0])
    with pytest.raises(rbss.RbssError) as e:
        rbss.compile(os.path.join(ROOT, "models", "no_such_model.toml"))
    assert "no_such_model.toml: cannot read" in str(e.value)


def test_out_arrays_are_written_and_returned(robot):
    x = robot.ik(pose_near_home(robot, 0.01))
    xdot = robot.velocity(x, [0.05, -0.02, 0.1, 0.0, 0.1, -0.1])
    u = np.array([100.0, -200.0, 300.0, 0.0, 50.0, 10.0])
    xddot, lam = robot.forward_dynamics(x, xdot, u)
    out = (np.full(24, np.nan), np.full(18, np.nan))
    a, b = robot.forward_dynamics(x, xdot, u, out=out)
    assert a is out[0] and b is out[1]
    np.testing.assert_array_equal(a, xddot)
    np.testing.assert_array_equal(b, lam)
    # Batched, into (k, n) arrays.
    xs, xdots, us = (np.stack([v, v]) for v in (x, xdot, u))
    outs = (np.empty((2, 24)), np.empty((2, 18)))
    robot.forward_dynamics(xs, xdots, us, out=outs)
    np.testing.assert_array_equal(outs[0][1], xddot)
    f = np.empty(18)
    assert robot.constraints(x, out=f) is f and np.max(np.abs(f)) < 1e-12
    with pytest.raises(ValueError, match="out: expected"):
        robot.forward_dynamics(x, xdot, u, out=(np.empty(24), np.empty(17)))
    with pytest.raises(ValueError, match="out: expected"):
        robot.forward_dynamics(x, xdot, u, out=np.empty(24))
    with pytest.raises(ValueError, match="out: expected"):
        robot.constraints(x, out=np.empty(18, dtype=np.float32))
    frozen = np.empty(18)
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match="out: expected a writable"):
        robot.constraints(x, out=frozen)
    # An output over an input's memory, or over the other output's.
    with pytest.raises(ValueError, match="shares memory"):
        robot.forward_dynamics(x, xdot, u, out=(x, np.empty(18)))
    both = np.empty(24)
    with pytest.raises(ValueError, match="shares memory"):
        robot.forward_dynamics(x, xdot, u, out=(both, both[:18]))
    start = robot.home.copy()
    with pytest.raises(ValueError, match="shares memory"):
        robot.ik(pose_near_home(robot, 0.0), x_start=start, out=start)


def test_accelerations_satisfy_the_constraints(robot):
    x = robot.ik(pose_near_home(robot, 0.01))
    xdot = robot.velocity(x, [0.05, -0.02, 0.1, 0.0, 0.1, -0.1])
    xddot = robot.acceleration(x, xdot, [0.1, 0.2, -0.3, 0.0, 0.1, 0.0])
    G = robot.jacobian(x)
    assert np.max(np.abs(G @ xddot - robot.gamma(x, xdot))) < 1e-9
    np.testing.assert_allclose(xddot[robot.output_index], [0.1, 0.2, -0.3, 0.0, 0.1, 0.0], atol=1e-12)
    back = robot.forward_acceleration(x, xdot, xddot[robot.actuated_index])
    np.testing.assert_allclose(back, xddot, atol=1e-9)


def test_both_implementations_agree_bit_for_bit(robot, ctypes_robot):
    rng = np.random.default_rng(3)
    x = robot.ik(pose_near_home(robot, 0.015))
    xdot = robot.velocity(x, rng.uniform(-0.1, 0.1, 6))
    u = rng.uniform(-300, 300, 6)
    for name, args in [
        ("ik", (pose_near_home(robot, 0.015),)),
        ("fk", (x[robot.actuated_index],)),
        ("velocity", (x, xdot[robot.output_index])),
        ("inverse_dynamics", (x, xdot, np.ones(24))),
        ("forward_dynamics", (x, xdot, u)),
        ("energy", (x, xdot)),
        ("jacobian", (x,)),
        ("mass_matrix", (np.stack([x, x]),)),
        ("psi", (x, xdot)),
    ]:
        a, b = getattr(robot, name)(*args), getattr(ctypes_robot, name)(*args)
        for p, q in zip(a if isinstance(a, tuple) else (a,), b if isinstance(b, tuple) else (b,)):
            assert p.shape == q.shape, name
            np.testing.assert_array_equal(p, q, err_msg=name)
    assert robot.home.shape == (24,) and robot.home is robot.home
    np.testing.assert_array_equal(robot.home, ctypes_robot.home)
    assert robot.constraint_names == ctypes_robot.constraint_names
