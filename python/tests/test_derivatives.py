"""The derivative methods (issue 36) on the 6-UPS, both implementations: forward_dynamics_derivatives,
linearize and step_derivatives against central differences of the layer's own forward dynamics
(relative error <= 1e-6 of each matrix's largest entry), inverse_dynamics_derivatives against
central differences of its inverse_dynamics; linearize along the constraint manifold
(y perturbed, the positions re-solved by ik or fk, the velocities by velocity or
forward_velocity); step_derivatives against an RK4 / semi-implicit Euler step written here on
forward_dynamics. Shapes, batches (rows equal to single calls) and refusals (a state off the
manifold, a NaN, a bad option or shape).
"""

import os

import numpy as np
import pytest

import rbss

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MODEL = os.path.join(ROOT, "models", "stewart_6ups.toml")
REL = 1e-6


@pytest.fixture(scope="module", params=["native", "ctypes"])
def robot(request):
    if request.param == "native" and not rbss.native_available():
        if os.environ.get("RBSS_REQUIRE_NATIVE") == "1":
            pytest.fail("rbss._native is not importable (RBSS_REQUIRE_NATIVE=1)")
        pytest.skip("rbss._native is not built")
    return rbss.compile(MODEL, backend=request.param)


def state(robot):
    """A moving state on the manifold near the home, and forces around the holding ones."""
    pose = robot.home[robot.output_index].copy()
    pose[0] += 0.01
    pose[4] -= 0.03
    x = robot.ik(pose)
    xdot = robot.velocity(x, [0.05, -0.02, 0.1, 0.0, 0.1, -0.1])
    u, _ = robot.inverse_dynamics(x, np.zeros(robot.n), np.zeros(robot.n))
    return x, xdot, u + np.array([30.0, -20.0, 10.0, 40.0, -50.0, 25.0])


def step(v):
    return np.cbrt(np.finfo(float).eps) * max(1.0, abs(v))


def central(f, p):
    """Central differences of f (an array of any shape) at the vector p: (f.shape + (len(p),))."""
    cols = []
    for j in range(len(p)):
        h = step(p[j])
        plus, minus = p.copy(), p.copy()
        plus[j] += h
        minus[j] -= h
        cols.append((f(plus) - f(minus)) / (plus[j] - minus[j]))
    return np.stack(cols, axis=-1)


def assert_rel(what, got, want):
    assert got.shape == want.shape, (what, got.shape, want.shape)
    scale = np.max(np.abs(want))
    assert scale > 0, what
    err = np.max(np.abs(got - want)) / scale
    assert err <= REL, f"{what}: relative error {err:.2e} (largest entry {scale:.3e})"


def test_forward_dynamics_derivatives_against_central_differences(robot):
    x, xdot, u = state(robot)
    d = robot.forward_dynamics_derivatives(x, xdot, u)
    n, m, a = robot.n, robot.m, robot.actuated
    shapes = {
        "xddot": (n,),
        "lambda": (m,),
        "dxddot_dx": (n, n),
        "dxddot_dxdot": (n, n),
        "dxddot_du": (n, a),
        "dlambda_dx": (m, n),
        "dlambda_dxdot": (m, n),
        "dlambda_du": (m, a),
    }
    assert {k: v.shape for k, v in d.items()} == shapes
    xddot, lam = robot.forward_dynamics(x, xdot, u)
    np.testing.assert_array_equal(d["xddot"], xddot)
    np.testing.assert_array_equal(d["lambda"], lam)

    def fd(x_, v_, u_):
        xdd, la = robot.forward_dynamics(x_, v_, u_)
        return np.concatenate([xdd, la])

    for wrt, p, f in [
        ("dx", x, lambda p: fd(p, xdot, u)),
        ("dxdot", xdot, lambda p: fd(x, p, u)),
        ("du", u, lambda p: fd(x, xdot, p)),
    ]:
        num = central(f, p)
        assert_rel(f"dxddot_{wrt}", d[f"dxddot_{wrt}"], num[:n])
        assert_rel(f"dlambda_{wrt}", d[f"dlambda_{wrt}"], num[n:])


def test_inverse_dynamics_derivatives_against_central_differences(robot):
    x, xdot, u = state(robot)
    xddot, _ = robot.forward_dynamics(x, xdot, u)
    xddot = xddot + 0.1  # off the acceleration constraint too: the derivatives hold anywhere
    d = robot.inverse_dynamics_derivatives(x, xdot, xddot)
    n, m, a = robot.n, robot.m, robot.actuated
    shapes = {
        "u": (a,),
        "lambda": (m,),
        "du_dx": (a, n),
        "du_dxdot": (a, n),
        "du_dxddot": (a, n),
        "dlambda_dx": (m, n),
        "dlambda_dxdot": (m, n),
        "dlambda_dxddot": (m, n),
    }
    assert {k: v.shape for k, v in d.items()} == shapes
    uu, lam = robot.inverse_dynamics(x, xdot, xddot)
    np.testing.assert_array_equal(d["u"], uu)
    np.testing.assert_array_equal(d["lambda"], lam)
    # At forward dynamics' own acceleration, inverse dynamics gives back the forces.
    at_fd = robot.inverse_dynamics_derivatives(x, xdot, robot.forward_dynamics(x, xdot, u)[0])
    np.testing.assert_allclose(at_fd["u"], u, rtol=0, atol=1e-9 * np.max(np.abs(u)))

    def inv(x_, v_, a_):
        u_, la = robot.inverse_dynamics(x_, v_, a_)
        return np.concatenate([u_, la])

    for wrt, p, f in [
        ("dx", x, lambda p: inv(p, xdot, xddot)),
        ("dxdot", xdot, lambda p: inv(x, p, xddot)),
        ("dxddot", xddot, lambda p: inv(x, xdot, p)),
    ]:
        num = central(f, p)
        assert_rel(f"du_{wrt}", d[f"du_{wrt}"], num[:a])
        assert_rel(f"dlambda_{wrt}", d[f"dlambda_{wrt}"], num[a:])


@pytest.mark.parametrize("coordinates", ["outputs", "actuated"])
def test_linearize_along_the_manifold(robot, coordinates):
    x, xdot, u = state(robot)
    A, B = robot.linearize(x, xdot, u, coordinates=coordinates)
    d = robot.n - robot.m
    assert A.shape == (2 * d, 2 * d) and B.shape == (2 * d, robot.actuated)
    if coordinates == "outputs":
        idx = robot.output_index

        def on_manifold(y, ydot):
            xs = robot.ik(y, x_start=x)
            return xs, robot.velocity(xs, ydot)
    else:
        idx = robot.actuated_index

        def on_manifold(y, ydot):
            xs = robot.fk(y, x_start=x)
            return xs, robot.forward_velocity(xs, ydot)

    y, ydot = x[idx], xdot[idx]
    # The state is the manifold's point of (y, ydot): the map round-trips.
    xs, vs = on_manifold(y, ydot)
    np.testing.assert_allclose(xs, x, atol=1e-12)
    np.testing.assert_allclose(vs, xdot, atol=1e-12)

    def yddot(y_, ydot_, u_):
        xs, vs = on_manifold(y_, ydot_)
        return robot.forward_dynamics(xs, vs, u_)[0][idx]

    want_a = np.zeros((2 * d, 2 * d))
    want_a[:d, d:] = np.eye(d)
    want_a[d:, :d] = central(lambda p: yddot(p, ydot, u), y)
    want_a[d:, d:] = central(lambda p: yddot(y, p, u), ydot)
    want_b = np.zeros((2 * d, robot.actuated))
    want_b[d:] = central(lambda p: yddot(y, ydot, p), u)
    assert_rel(f"A ({coordinates})", A, want_a)
    assert_rel(f"B ({coordinates})", B, want_b)
    np.testing.assert_array_equal(A[:d], want_a[:d])


def rk4(robot, x, v, u, h):
    acc = lambda x_, v_: robot.forward_dynamics(x_, v_, u)[0]  # noqa: E731
    k1 = (v, acc(x, v))
    k2 = (v + h / 2 * k1[1], acc(x + h / 2 * k1[0], v + h / 2 * k1[1]))
    k3 = (v + h / 2 * k2[1], acc(x + h / 2 * k2[0], v + h / 2 * k2[1]))
    k4 = (v + h * k3[1], acc(x + h * k3[0], v + h * k3[1]))
    x1 = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
    v1 = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return x1, v1


def euler(robot, x, v, u, h):
    v1 = v + h * robot.forward_dynamics(x, v, u)[0]
    return x + h * v1, v1


@pytest.mark.parametrize("method,written", [("rk4", rk4), ("semi_implicit_euler", euler)])
def test_step_derivatives_against_central_differences(robot, method, written):
    x, xdot, u = state(robot)
    n, h = robot.n, 2e-3
    x1, v1, fx, fu = robot.step_derivatives(x, xdot, u, h, method=method)
    assert x1.shape == v1.shape == (n,)
    assert fx.shape == (2 * n, 2 * n) and fu.shape == (2 * n, robot.actuated)
    wx, wv = written(robot, x, xdot, u, h)
    np.testing.assert_allclose(x1, wx, rtol=0, atol=1e-13)
    np.testing.assert_allclose(v1, wv, rtol=0, atol=1e-11)

    def s1(s, u_):
        return np.concatenate(written(robot, s[:n], s[n:], u_, h))

    s = np.concatenate([x, xdot])
    assert_rel(f"F_x ({method})", fx, central(lambda p: s1(p, u), s))
    assert_rel(f"F_u ({method})", fu, central(lambda p: s1(s, p), u))


def test_batches_are_rows_of_single_calls(robot):
    x, xdot, u = state(robot)
    x2 = robot.ik(robot.home[robot.output_index])
    xs, vs, us = np.stack([x, x2]), np.stack([xdot, np.zeros(robot.n)]), np.stack([u, u])
    d = robot.n - robot.m
    batch = robot.forward_dynamics_derivatives(xs, vs, us)
    assert batch["dxddot_dx"].shape == (2, robot.n, robot.n)
    assert batch["dlambda_du"].shape == (2, robot.m, robot.actuated)
    inv = robot.inverse_dynamics_derivatives(xs, vs, np.stack([xdot, xdot]))
    assert inv["du_dxddot"].shape == (2, robot.actuated, robot.n)
    assert inv["dlambda_dx"].shape == (2, robot.m, robot.n)
    A, B = robot.linearize(xs, vs, us)
    assert A.shape == (2, 2 * d, 2 * d) and B.shape == (2, 2 * d, robot.actuated)
    x1, v1, fx, fu = robot.step_derivatives(xs, vs, us, 1e-3)
    assert x1.shape == (2, robot.n) and fx.shape == (2, 2 * robot.n, 2 * robot.n)
    for i in range(2):
        one = robot.forward_dynamics_derivatives(xs[i], vs[i], us[i])
        for k, v in one.items():
            np.testing.assert_array_equal(batch[k][i], v, err_msg=k)
        one = robot.inverse_dynamics_derivatives(xs[i], vs[i], xdot)
        for k, v in one.items():
            np.testing.assert_array_equal(inv[k][i], v, err_msg=k)
        a1, b1 = robot.linearize(xs[i], vs[i], us[i])
        np.testing.assert_array_equal(A[i], a1)
        np.testing.assert_array_equal(B[i], b1)
        s = robot.step_derivatives(xs[i], vs[i], us[i], 1e-3)
        for got, want in zip((x1[i], v1[i], fx[i], fu[i]), s):
            np.testing.assert_array_equal(got, want)
    # Baumgarte's gains change the step's Jacobian (they enter every stage's acceleration).
    plain = robot.step_derivatives(x, xdot, u, 1e-3)[2]
    stab = robot.step_derivatives(x, xdot, u, 1e-3, baumgarte=[10.0, 10.0])[2]
    assert np.max(np.abs(stab - plain)) > 1e-6


def test_refusals(robot):
    x, xdot, u = state(robot)
    off = x.copy()
    off[robot.output_index[2]] += 0.01
    with pytest.raises(rbss.RbssError, match="not on the constraint manifold") as e:
        robot.linearize(off, xdot, u)
    assert e.value.code == rbss.RBSS_ERR_STATE
    bad = x.copy()
    bad[3] = np.nan
    for call in (
        lambda: robot.forward_dynamics_derivatives(bad, xdot, u),
        lambda: robot.linearize(bad, xdot, u),
        lambda: robot.step_derivatives(bad, xdot, u, 1e-3),
        lambda: robot.inverse_dynamics_derivatives(bad, xdot, xdot),
    ):
        with pytest.raises(rbss.RbssError, match=r"`x`\[3\] is not finite") as e:
            call()
        assert e.value.code == rbss.RBSS_ERR_ARGUMENT
    with pytest.raises(rbss.RbssError, match="`dt` = -0.001") as e:
        robot.step_derivatives(x, xdot, u, -1e-3)
    assert e.value.code == rbss.RBSS_ERR_ARGUMENT
    # Rates so large that the velocity-squared terms overflow.
    huge = np.full(robot.n, 1e200)
    with pytest.raises(rbss.RbssError, match="non-finite") as e:
        robot.forward_dynamics_derivatives(x, huge, u)
    assert e.value.code == rbss.RBSS_ERR_NONFINITE
    with pytest.raises(ValueError, match="coordinates: expected 'outputs' or 'actuated', got 'pose'"):
        robot.linearize(x, xdot, u, coordinates="pose")
    with pytest.raises(ValueError, match="method: expected 'rk4' or 'semi_implicit_euler', got 'euler'"):
        robot.step_derivatives(x, xdot, u, 1e-3, method="euler")
    with pytest.raises(ValueError, match=r"u: expected shape \(6,\) or \(k, 6\), got \(5,\)"):
        robot.forward_dynamics_derivatives(x, xdot, u[:5])
    with pytest.raises(ValueError, match=r"xddot: expected shape \(24,\) or \(k, 24\), got \(23,\)"):
        robot.inverse_dynamics_derivatives(x, xdot, xdot[:23])
    with pytest.raises(ValueError, match=r"baumgarte: expected shape \(2,\), got \(3,\)"):
        robot.step_derivatives(x, xdot, u, 1e-3, baumgarte=[1.0, 2.0, 3.0])
