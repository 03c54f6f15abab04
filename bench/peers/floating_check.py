#!/usr/bin/env python3
"""bench/peers/floating_check.py -- a floating base against Pinocchio's free-flyer and MuJoCo's
free joint (issue 34, item 3).

    floating_check.py RBSS BUILD_DIR [N_STATES]

The robot: tests/data/floating_biped.urdf (a trunk on a URDF `floating` joint, two legs of three
revolute joints), imported by rbss with the one-line tests/data/floating_biped.toml. rbss's
base is X = [x, y, z, qw, qx, qy, qz] (world position, quaternion scalar first, its unit norm a
constraint row); the peers' velocities are mapped to rbss's by Xdot = A v:

- Pinocchio (free-flyer, q = [x, y, z, qx, qy, qz, qw]): v = (R^T pdot, omega_body, thetadot),
  so A = diag(R, Q(q) / 2, 1) with Q(q) omega = q * (0, omega);
- MuJoCo (free joint, qpos = [x, y, z, qw, qx, qy, qz]): v = (pdot, omega_body, thetadot),
  A = diag(1, Q(q) / 2, 1).

Compared at random states (unit q, Xdot tangent): M_peer = A^T M A; bias_peer (nle, qfrc_bias)
= A^T (M Adot v - psi); the accelerations vdot = A^+ (Xddot - Adot v) with rbss's Xddot (`rbss
eval --model-file` with U) against Pinocchio's aba and MuJoCo's qacc (joint torques U, no
contact); and with one foot held at a world point (an rbss `ball` loop in a model file of its
own, Pinocchio's constraintDynamics with a CONTACT_3D, LOCAL, no Baumgarte). Relative error:
max |a - b| / max(1, max |b|).
"""

import json
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
URDF = os.path.join(ROOT, "tests", "data", "floating_biped.urdf")
JOINTS = ["hip_roll_l", "hip_pitch_l", "knee_l", "hip_roll_r", "hip_pitch_r", "knee_r"]
FOOT = ("shin_l", "knee_l", [0.0, 0.0, -0.3])  # link, its joint, the foot point in the link


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr[-3000:]}")
    return r.stdout


def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))


def quat_matrix(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def Q(q):
    """q * (0, omega) = Q(q) omega (Hamilton product, scalar first)."""
    w, x, y, z = q
    return np.array([[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]])


def maps(x, v, local_linear):
    """A (13 x 12) and Adot v (13) for the peer's velocity v at rbss's X = x."""
    q = x[3:7]
    R = quat_matrix(q)
    A = np.zeros((13, 12))
    A[0:3, 0:3] = R if local_linear else np.eye(3)
    A[3:7, 3:6] = 0.5 * Q(q)
    A[7:, 6:] = np.eye(6)
    w = v[3:6]
    qd = 0.5 * Q(q) @ w
    adv = np.zeros(13)
    if local_linear:
        adv[0:3] = R @ np.cross(w, v[0:3])
    adv[3:7] = 0.5 * Q(qd) @ w
    return A, adv


def rbss_eval(rbss, build, model_file, states):
    path = os.path.join(build, "floating_states.json")
    with open(path, "w") as f:
        json.dump({"states": states}, f)
    return json.loads(run([rbss, "eval", "--model-file", model_file, "--states", path]))["states"]


def main():
    rbss, build = sys.argv[1], sys.argv[2]
    n_states = int(sys.argv[3]) if len(sys.argv) > 3 else 20
    os.makedirs(build, exist_ok=True)
    import mujoco
    import pinocchio as pin

    # Pinocchio: the URDF's floating joint is its free-flyer.
    model = pin.buildModelFromUrdf(URDF)
    data = model.createData()
    assert model.nq == 13 and model.nv == 12, (model.nq, model.nv)
    assert [model.names[i] for i in range(2, model.njoints)] == JOINTS, list(model.names)
    # MuJoCo: the same URDF (its floating joint becomes a free joint), nothing fused.
    with open(URDF) as f:
        text = f.read()
    text = text.replace(
        '<robot name="floating_biped">',
        '<robot name="floating_biped">\n  <mujoco><compiler discardvisual="false" '
        'fusestatic="false" balanceinertia="false" strippath="false"/></mujoco>')
    mpath = os.path.join(build, "floating_biped_mj.urdf")
    with open(mpath, "w") as f:
        f.write(text)
    mm = mujoco.MjModel.from_xml_path(mpath)
    # The URDF's <limit>s become MuJoCo joint limits (constraints) at the random angles: off,
    # as rbss has none (limits are ignored by its importer).
    mm.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_LIMIT)
    md = mujoco.MjData(mm)
    assert mm.nq == 13 and mm.nv == 12 and int(mm.jnt_type[0]) == int(mujoco.mjtJoint.mjJNT_FREE)
    assert [mujoco.mj_id2name(mm, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(1, 7)] == JOINTS

    free_file = os.path.join(build, "floating_biped.toml")
    with open(free_file, "w") as f:
        f.write(f'urdf = "{URDF}"\n')
    # The same robot standing on its left foot: a ball loop at the foot, the world point at the
    # origin; states put the base where the foot reaches it.
    stance_file = os.path.join(build, "floating_biped_stance.toml")
    with open(stance_file, "w") as f:
        f.write(f'urdf = "{URDF}"\n\n[[loop]]\nname = "stance"\n'
                f'a = {{ body = "{FOOT[0]}", transforms = ["Tz({FOOT[2][2]})"] }}\n'
                'b = { body = "world" }\n')

    rng = np.random.default_rng(34)
    states, peer = [], []
    for _ in range(n_states):
        x = rng.uniform(-1, 1, 13)
        x[3:7] /= np.linalg.norm(x[3:7])
        xd = rng.uniform(-2, 2, 13)
        xd[3:7] -= (x[3:7] @ xd[3:7]) * x[3:7]
        u = rng.uniform(-10, 10, 6)
        states.append({"X": list(x), "Xdot": list(xd), "U": list(u)})
    ev = rbss_eval(rbss, build, free_file, states)
    worst = {k: 0.0 for k in ["M pin", "bias pin", "acc pin", "M mj", "bias mj", "acc mj",
                              "M pin-mj"]}
    for s, e in zip(states, ev):
        x, xd, u = np.array(s["X"]), np.array(s["Xdot"]), np.array(s["U"])
        M, psi, xdd = np.array(e["M"]), np.array(e["psi"]), np.array(e["Xddot"])
        R = quat_matrix(x[3:7])
        w_body = 2 * (Q(x[3:7]).T @ xd[3:7])
        tau = np.concatenate([np.zeros(6), u])
        # Pinocchio: q = [p, qx, qy, qz, qw, theta], v = [R^T pdot, omega_body, thetadot].
        qp = np.concatenate([x[0:3], x[4:7], x[3:4], x[7:]])
        vp = np.concatenate([R.T @ xd[0:3], w_body, xd[7:]])
        Mp = pin.crba(model, data, qp)
        Mp = np.triu(Mp) + np.triu(Mp, 1).T
        bp = pin.nonLinearEffects(model, data, qp, vp)
        ap = pin.aba(model, data, qp, vp, tau)
        A, adv = maps(x, vp, True)
        Ap = np.linalg.pinv(A)
        worst["M pin"] = max(worst["M pin"], rel(A.T @ M @ A, Mp))
        worst["bias pin"] = max(worst["bias pin"], rel(A.T @ (M @ adv - psi), bp))
        worst["acc pin"] = max(worst["acc pin"], rel(Ap @ (xdd - adv), ap))
        # MuJoCo: qpos = [p, qw, qx, qy, qz, theta], qvel = [pdot, omega_body, thetadot].
        vm = np.concatenate([xd[0:3], w_body, xd[7:]])
        md.qpos[:], md.qvel[:], md.qfrc_applied[:] = x, vm, tau
        md.ctrl[:] = 0
        mujoco.mj_forward(mm, md)
        Mm = np.zeros((12, 12))
        mujoco.mj_fullM(mm, md, Mm)
        A, adv = maps(x, vm, False)
        Am = np.linalg.pinv(A)
        worst["M mj"] = max(worst["M mj"], rel(A.T @ M @ A, Mm))
        worst["bias mj"] = max(worst["bias mj"], rel(A.T @ (M @ adv - psi), md.qfrc_bias))
        worst["acc mj"] = max(worst["acc mj"], rel(Am @ (xdd - adv), md.qacc))
        # the peers with each other, in MuJoCo's coordinates: M_mj = T^T M_pin T, v_pin = T v_mj
        T = np.eye(12)
        T[0:3, 0:3] = R.T
        worst["M pin-mj"] = max(worst["M pin-mj"], rel(T.T @ Mp @ T, Mm))

    # Standing on the left foot: the base placed so that the foot is at the world origin;
    # Xdot in the null space of G (rbss's, at the state).
    jfoot = model.getJointId(FOOT[1])
    place = pin.SE3(np.eye(3), np.array(FOOT[2]))
    cms = pin.StdVec_RigidConstraintModel([pin.RigidConstraintModel(
        pin.ContactType.CONTACT_3D, model, jfoot, place, 0, pin.SE3.Identity(),
        pin.ReferenceFrame.LOCAL)])
    cds = pin.StdVec_RigidConstraintData([c.createData() for c in cms])
    pin.initConstraintDynamics(model, data, cms, cds)
    prox = pin.ProximalSettings(1e-14, 1e-12, 200)
    X = []
    for s in states:
        x = np.array(s["X"])
        qp = np.concatenate([x[0:3], x[4:7], x[3:4], x[7:]])
        pin.forwardKinematics(model, data, qp)
        foot = data.oMi[jfoot].act(np.array(FOOT[2]))
        x[0:3] -= foot
        X.append(x)
    zero = [0.0] * 13
    ev0 = rbss_eval(rbss, build, stance_file, [{"X": list(x), "Xdot": zero} for x in X])
    cstates = []
    fmax = 0.0
    for x, e, s in zip(X, ev0, states):
        fmax = max(fmax, float(np.max(np.abs(e["f"]))))
        G = np.array(e["G"])
        _, sv, vt = np.linalg.svd(G)
        N = vt[G.shape[0]:].T
        xd = N @ rng.uniform(-2, 2, N.shape[1])
        cstates.append({"X": list(x), "Xdot": list(xd), "U": s["U"]})
    ev = rbss_eval(rbss, build, stance_file, cstates)
    worst["acc pin, stance"] = 0.0
    for s, e in zip(cstates, ev):
        x, xd, u = np.array(s["X"]), np.array(s["Xdot"]), np.array(s["U"])
        R = quat_matrix(x[3:7])
        w_body = 2 * (Q(x[3:7]).T @ xd[3:7])
        qp = np.concatenate([x[0:3], x[4:7], x[3:4], x[7:]])
        vp = np.concatenate([R.T @ xd[0:3], w_body, xd[7:]])
        tau = np.concatenate([np.zeros(6), u])
        ap = pin.constraintDynamics(model, data, qp, vp, tau, cms, cds, prox)
        A, adv = maps(x, vp, True)
        xdd = np.array(e["Xddot"])
        worst["acc pin, stance"] = max(worst["acc pin, stance"],
                                       rel(np.linalg.pinv(A) @ (xdd - adv), ap))
    print(f"floating_biped, {n_states} random states (unit q, Xdot tangent), "
          f"max |f| of the stance states {fmax:.1e}; pinocchio {pin.__version__}, "
          f"mujoco {mujoco.__version__}")
    for k, v in worst.items():
        print(f"  {k:18s} {v:.1e}")


if __name__ == "__main__":
    main()
