#!/usr/bin/env python3
"""bench/peers/import_check.py -- rbss's imported models against MuJoCo and Pinocchio loading
the same source files (issue 21). Run by import.sh (see README.md there):

    import_check.py BUILD RBSS OUT.md

For each test source of codegen/tests/import/ (URDF, MJCF, SDF) and its model file, at N random
states on the loops (Newton on rbss's own f, G; velocities in G's null space): rbss's M, psi and
forward dynamics (`rbss eval --model-file`, with random U), MuJoCo's mj_fullM / qfrc_bias /
constrained accelerations and Pinocchio's crba / nle / constraintDynamics, coordinates mapped by
joint name. Relative error: max |a - b| / max(1, max |b|), b the peer's value.
"""

import datetime
import json
import os
import platform
import re
import subprocess
import sys
import tomllib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
SRC = os.path.join(ROOT, "codegen", "tests", "import")
N_STATES = int(os.environ.get("IMPORT_STATES", "20"))
SEED = 21

# name, model file, the file the peers load, the file whose homes start Newton, note
CASES = [
    ("ur5_urdf", "ur5.toml", "ur5.urdf", "ur5.toml", ""),
    ("stewart_6ups_mjcf", os.path.join(HERE, "import", "stewart_6ups.toml"), "stewart_6ups.xml",
     os.path.join(ROOT, "models", "stewart_6ups.toml"),
     "the model file is `bench/peers/import/stewart_6ups.toml`: codegen/tests/import/"
     "stewart_6ups.toml with models/stewart_6ups.toml's home (the test's file has none, and "
     "at zero the 6-UPS does not assemble: `rbss-codegen` refuses it, \"the home "
     "configuration does not assemble\")"),
    ("four_bar_mjcf", "four_bar_mjcf.toml", "four_bar.xml", "four_bar.toml", ""),
    ("four_bar_split", "four_bar_split.toml", "four_bar_split.xml", "four_bar.toml", ""),
    ("four_bar_sdf", "four_bar_sdf.toml", "four_bar.sdf", "four_bar.toml",
     "no peer reads SDF here (MuJoCo does not; the `pin` wheel is built without sdformat): "
     "the peers load four_bar.xml, the same four-bar in MJCF"),
]


def die(msg):
    print(f"bench/peers: ERROR: {msg}", file=sys.stderr)
    sys.exit(1)


def run(cmd, stdin=None):
    r = subprocess.run(cmd, capture_output=True, text=True, input=stdin)
    if r.returncode != 0:
        die(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stderr[-3000:]}")
    return r.stdout


def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))


# ---- rbss -----------------------------------------------------------------------------------
class Rbss:
    def __init__(self, rbss, build, model_file):
        self.rbss, self.build, self.model_file = rbss, build, model_file
        # the names: `rbss list` knows the compiled-in robots only, so the coordinates and the
        # actuated ones come from the library's C ABI (python/rbss, the same --model-file cache)
        sys.path.insert(0, os.path.join(ROOT, "python"))
        os.environ["RBSS"] = rbss
        import rbss as rbss_py
        robot = rbss_py.compile(model_file)
        self.coords = list(robot.coordinates)
        self.actuated = [self.coords[i] for i in robot.actuated_index]
        # the generated home (a task frame's coordinates are not in the model file: their home
        # is the frame's pose at the joints' home, computed by rbss)
        self.home = dict(zip(self.coords, map(float, robot.home)))

    def eval(self, states):
        path = os.path.join(self.build, "import_states.json")
        with open(path, "w") as f:
            json.dump({"states": states}, f)
        return json.loads(run([self.rbss, "eval", "--model-file", self.model_file,
                               "--states", path]))["states"]


def homes(toml_path):
    with open(toml_path, "rb") as f:
        doc = tomllib.load(f)
    h = {}
    for c in doc.get("coordinates", []):
        if isinstance(c.get("home"), (int, float)):
            h[c["name"]] = float(c["home"]) * (np.pi / 180 if c.get("unit") == "deg" else 1)
    return h


def random_states(rb, guess, rng):
    """N states on the loops: Newton (min-norm steps) on f from the guess's homes, each coordinate
    moved by up to 0.1; velocities in G's null space; U random."""
    n = len(rb.coords)
    X = np.array([[guess.get(c, 0.0) + rng.uniform(-0.1, 0.1) for c in rb.coords]
                  for _ in range(N_STATES)])
    zero = [0.0] * n
    for it in range(40):
        ev = rb.eval([{"X": list(x), "Xdot": zero} for x in X])
        fmax = max((np.max(np.abs(e["f"])) if e["f"] else 0.0) for e in ev)
        if fmax < 1e-14:
            break
        for i, e in enumerate(ev):
            if e["f"]:
                X[i] -= np.linalg.pinv(np.array(e["G"])) @ np.array(e["f"])
    else:
        die(f"{rb.model_file}: Newton did not reach the loops (max |f| = {fmax:.1e})")
    states = []
    for x, e in zip(X, ev):
        G = np.array(e["G"]).reshape(-1, n)
        if G.shape[0]:
            _, s, vt = np.linalg.svd(G)
            rank = int(np.sum(s > 1e-10 * s[0]))
            N = vt[rank:].T
        else:
            N = np.eye(n)
        xd = N @ rng.uniform(-1, 1, N.shape[1])
        u = rng.uniform(-10, 10, len(rb.actuated))
        states.append({"X": list(x), "Xdot": list(xd), "U": list(u)})
    return states, fmax, it


# ---- MuJoCo ---------------------------------------------------------------------------------
class MuJoCo:
    def __init__(self, path):
        import mujoco
        self.mj = mujoco
        self.m = mujoco.MjModel.from_xml_path(path)
        self.d = mujoco.MjData(self.m)
        m = self.m
        self.joint = {}  # name -> (qpos adr, dof adr)
        for j in range(m.njnt):
            if int(m.jnt_type[j]) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
                die(f"{path}: joint {j} is neither hinge nor slide")
            self.joint[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)] = (
                m.jnt_qposadr[j], m.jnt_dofadr[j])

    def names(self):
        return list(self.joint)

    def at(self, q, v, tau):
        mj, m, d = self.mj, self.m, self.d
        d.qpos[:], d.qvel[:], d.qfrc_applied[:] = q, v, tau
        d.ctrl[:] = 0
        mj.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mj.mj_fullM(m, d, M)
        return M

    def points(self):
        """The connect equalities' two points: [(body1, world point, body2, world point)]."""
        mj, m, d = self.mj, self.m, self.d
        out = []
        for e in range(m.neq):
            if int(m.eq_type[e]) != int(mj.mjtEq.mjEQ_CONNECT):
                die("only connect equalities are handled")
            o1, o2 = m.eq_obj1id[e], m.eq_obj2id[e]
            if int(m.eq_objtype[e]) == int(mj.mjtObj.mjOBJ_SITE):
                out.append((m.site_bodyid[o1], d.site_xpos[o1].copy(),
                            m.site_bodyid[o2], d.site_xpos[o2].copy()))
            else:  # body1, body2 with anchors in each (eq_data[0:3], eq_data[3:6])
                p1 = d.xpos[o1] + d.xmat[o1].reshape(3, 3) @ m.eq_data[e, 0:3]
                p2 = d.xpos[o2] + d.xmat[o2].reshape(3, 3) @ m.eq_data[e, 3:6]
                out.append((o1, p1, o2, p2))
        return out

    def constrained(self, tau_full):
        """Hard constraints: [M J'; J 0] [qacc; l] = [tau - qfrc_bias; -Jdot qvel] with MuJoCo's
        M (mj_fullM), qfrc_bias, J (mj_jac) and Jdot (mj_jacDot) at the connect points (rows that
        are zero everywhere, z of a planar loop, dropped)."""
        mj, m, d = self.mj, self.m, self.d
        M = np.zeros((m.nv, m.nv))
        mj.mj_fullM(m, d, M)
        rhs = tau_full - d.qfrc_bias + d.qfrc_passive
        Js, gs = [], []
        for b1, p1, b2, p2 in self.points():
            J = np.zeros((2, 3, m.nv))
            Jd = np.zeros((2, 3, m.nv))
            for k, (b, p) in enumerate(((b1, p1), (b2, p2))):
                mj.mj_jac(m, d, J[k], None, p, b)
                mj.mj_jacDot(m, d, Jd[k], None, p, b)
            Js.append(J[0] - J[1])
            gs.append(-(Jd[0] - Jd[1]) @ d.qvel)
        if not Js:
            return np.linalg.solve(M, rhs)
        J, g = np.vstack(Js), np.concatenate(gs)
        keep = np.max(np.abs(J), axis=1) > 1e-12
        J, g = J[keep], g[keep]
        k = J.shape[0]
        K = np.block([[M, J.T], [J, np.zeros((k, k))]])
        return np.linalg.solve(K, np.concatenate([rhs, g]))[: m.nv]


# ---- Pinocchio ------------------------------------------------------------------------------
def mjcf_one_tree(path, out):
    """Pinocchio 4.1.0's MJCF parser reads only the first body under <worldbody>: the same file
    with the worldbody's children inside one body without joints (fixed to the world, at the
    world's frame: the same mechanism), includes inlined."""
    import xml.etree.ElementTree as ET

    def inline(root, base):
        for parent in list(root.iter()):
            for i, ch in enumerate(list(parent)):
                if ch.tag == "include":
                    sub = ET.parse(os.path.join(base, ch.get("file"))).getroot()
                    inline(sub, base)
                    parent.remove(ch)
                    for k, e in enumerate(list(sub)):
                        parent.insert(i + k, e)
        return root

    root = inline(ET.parse(path).getroot(), os.path.dirname(path))
    wb = root.find("worldbody")
    wrap = ET.Element("body", {"name": "pinocchio_root"})
    for ch in list(wb):
        if ch.tag == "body":
            wb.remove(ch)
            wrap.append(ch)
    wb.append(wrap)
    ET.ElementTree(root).write(out)
    return out


class Pinocchio:
    def __init__(self, path, kind, build, mujoco_peer):
        import pinocchio as pin
        self.pin = pin
        self.notes = []
        if kind == "urdf":
            self.model = pin.buildModelFromUrdf(path)
        else:
            one = mjcf_one_tree(path, os.path.join(build, os.path.basename(path) + ".pin.xml"))
            self.model = pin.buildModelFromMJCF(one)
        self.model.gravity.linear = np.array(mujoco_peer.m.opt.gravity)
        self.data = self.model.createData()
        self.mjp = mujoco_peer
        # Pinocchio joint -> the names of its coordinates (a composite of a body's several
        # hinges is named after the first: Composite_NAME; its parts are the MuJoCo body's joints)
        mj, m = mujoco_peer.mj, mujoco_peer.m
        self.index = {}  # coordinate name -> (idx_q, idx_v)
        for jid in range(1, self.model.njoints):
            name = self.model.names[jid]
            jm = self.model.joints[jid]
            if jm.nq != jm.nv:
                die(f"{path}: Pinocchio joint {name} has nq != nv")
            if name.startswith("Composite_"):
                first = mj.mj_name2id(m, mj.mjtObj.mjOBJ_JOINT, name[len("Composite_"):])
                body = m.jnt_bodyid[first]
                parts = [mj.mj_id2name(m, mj.mjtObj.mjOBJ_JOINT, j)
                         for j in range(m.body_jntadr[body], m.body_jntadr[body] + m.body_jntnum[body])]
                if len(parts) != jm.nq:
                    die(f"{path}: composite {name} has {jm.nq} coordinates, body has {parts}")
            else:
                parts = [name]
            for k, p in enumerate(parts):
                self.index[p] = (jm.idx_q + k, jm.idx_v + k)

        self.anchors = None
        self.check_inertias(path)

    def check_inertias(self, path):
        """Each Pinocchio joint's inertia against the sum of MuJoCo's compiled inertias of the
        bodies it moves (at qpos0, in the joint's frame). Where they differ, Pinocchio's parse is
        noted and MuJoCo's inertias are used, so that the rest (kinematics, algorithms) is
        still compared."""
        pin, model = self.pin, self.model
        mj, m = self.mjp.mj, self.mjp.m
        d = mj.MjData(m)
        mj.mj_forward(m, d)
        data = model.createData()
        pin.forwardKinematics(model, data, pin.neutral(model))
        want = [pin.Inertia.Zero() for _ in range(model.njoints)]
        for b in range(1, m.nbody):
            jid = self.joint_of_body(b)
            if jid == 0 or m.body_mass[b] == 0:
                continue
            R = d.ximat[b].reshape(3, 3)
            Iw = pin.Inertia(m.body_mass[b], d.xipos[b].copy(), R @ np.diag(m.body_inertia[b]) @ R.T)
            want[jid] += data.oMi[jid].actInv(Iw)
        worst = 0.0
        for jid in range(1, model.njoints):
            a, b = model.inertias[jid].matrix(), want[jid].matrix()
            worst = max(worst, float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b))))))
        if worst > 1e-12:
            self.notes.append(
                f"Pinocchio's inertias from `{os.path.basename(path)}` differ from MuJoCo's "
                f"compiled ones by {worst:.1e} (relative, largest over its joints' 6x6 spatial "
                "inertias): the masses agree, but its centres of mass come out at the body frames' "
                "origins where MuJoCo puts them at the geoms' `pos` (here set by `<default>` "
                "classes; not investigated further). The row uses MuJoCo's inertias put into "
                "Pinocchio's joints, so that Pinocchio's kinematics and algorithms on this file "
                "are still compared")
            for jid in range(1, model.njoints):
                model.inertias[jid] = want[jid]
            self.data = model.createData()

    def names(self):
        return list(self.index)

    def joint_of_body(self, body):
        """The Pinocchio joint moving a MuJoCo body (its last joint, or its parent's)."""
        mj, m = self.mjp.mj, self.mjp.m
        while m.body_jntnum[body] == 0 and body != 0:
            body = m.body_parentid[body]
        if body == 0:
            return 0
        last = mj.mj_id2name(m, mj.mjtObj.mjOBJ_JOINT, m.body_jntadr[body] + m.body_jntnum[body] - 1)
        for jid in range(1, self.model.njoints):
            n = self.model.names[jid]
            if n == last:
                return jid
            if n.startswith("Composite_"):
                qi = self.index[last][0]
                jm = self.model.joints[jid]
                if jm.idx_q <= qi < jm.idx_q + jm.nq:
                    return jid
        die(f"no Pinocchio joint for MuJoCo joint {last}")

    def at(self, q, v):
        pin, model, data = self.pin, self.model, self.data
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        b = pin.nonLinearEffects(model, data, q, v)
        return M, b

    def constrained(self, q, v, tau):
        """constraintDynamics with one CONTACT_3D (LOCAL) per connect: its two points (MuJoCo's,
        at qpos0, where Pinocchio's q is its neutral) in Pinocchio's joint frames; no Baumgarte
        (Kp = Kd = 0); proximal settings mu = 1e-9 (a planar loop's z row is zero: the proximal
        iterations handle the singular Delassus matrix)."""
        pin, model, data = self.pin, self.model, self.data
        if self.anchors is None:
            mjp = self.mjp
            mjp.at(np.zeros(mjp.m.nq), np.zeros(mjp.m.nv), np.zeros(mjp.m.nv))
            d0 = model.createData()
            pin.forwardKinematics(model, d0, pin.neutral(model))
            self.anchors = []
            for b1, p1, b2, p2 in mjp.points():
                j1, j2 = self.joint_of_body(b1), self.joint_of_body(b2)
                self.anchors.append((j1, pin.SE3(np.eye(3), d0.oMi[j1].actInv(p1)),
                                     j2, pin.SE3(np.eye(3), d0.oMi[j2].actInv(p2))))
        if not self.anchors:
            return pin.aba(model, data, q, v, tau)
        cms = [pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, j1, pl1, j2, pl2,
                                        pin.ReferenceFrame.LOCAL)
               for j1, pl1, j2, pl2 in self.anchors]
        cms = pin.StdVec_RigidConstraintModel(cms)
        cds = pin.StdVec_RigidConstraintData([c.createData() for c in cms])
        pin.initConstraintDynamics(model, data, cms, cds)
        prox = pin.ProximalSettings(1e-14, 1e-9, 200)
        return pin.constraintDynamics(model, data, q, v, tau, cms, cds, prox)


# ---- one case -------------------------------------------------------------------------------
# public robot descriptions from the `example-robot-data` wheel (PyPI; import.sh downloads it):
# name, the URDF in the wheel, the flange link, a home of the joints away from singularities,
# joints besides the arm's six that are outputs too
ERD_VERSION = "6.0.0"
ERD = [
    ("erd_ur5", "robots/ur_description/urdf/ur5_robot.urdf", "tool0",
     [0.2, -1.3, 1.5, -1.8, -1.6, 0.3], []),
    ("erd_z1", "robots/z1_description/urdf/z1.urdf", "link06",
     [0.2, 1.0, -1.0, 0.5, 0.3, 0.2, 0.1], ["jointGripper"]),
]


def external(build):
    """The public URDFs out of the wheel, a model file for each (the URDF plus what rbss needs
    to take an open arm with inverse kinematics: the flange's pose as a task frame, the joints'
    home), and a copy without <visual>/<collision> for MuJoCo (whose URDF
    compiler would load the meshes, given as package:// paths)."""
    import glob
    import xml.etree.ElementTree as ET
    import zipfile

    import pinocchio as pin
    wheels = glob.glob(os.path.join(build, f"example_robot_data-{ERD_VERSION}-*.whl"))
    if not wheels:
        die(f"no example_robot_data {ERD_VERSION} wheel in {build} (import.sh downloads it)")
    d = os.path.join(build, "erd")
    os.makedirs(d, exist_ok=True)
    cases = []
    with zipfile.ZipFile(wheels[0]) as z:
        for name, inner, flange, qhome, extra in ERD:
            urdf = os.path.join(d, name + ".urdf")
            with open(urdf, "wb") as f:
                f.write(z.read("cmeel.prefix/share/example-robot-data/" + inner))
            root = ET.parse(urdf).getroot()
            for link in root.findall("link"):
                for e in link.findall("visual") + link.findall("collision"):
                    link.remove(e)
            mj_urdf = os.path.join(d, name + ".mujoco.urdf")
            ET.ElementTree(root).write(mj_urdf)
            model = pin.buildModelFromUrdf(urdf)
            joints = [model.names[j] for j in range(1, model.njoints)]
            lines = [f"# {name}: {inner} of the example-robot-data {ERD_VERSION} wheel, written by",
                     "# bench/peers/import_check.py: the flange's pose as a task frame, the home.",
                     f'urdf = "{name}.urdf"', "", "coordinates = ["]
            lines += [f'  {{ name = "{j}", home = {h!r} }},' for j, h in zip(joints, qhome)]
            # a joint besides the arm's (the z1's gripper) is actuated and must be an output
            outs = ", ".join([f'{{ frame = "{flange}", pose = "xyz-rpy" }}',
                              *(f'"{j}"' for j in extra)])
            lines += ["]", "", "[robot]", f'name = "{name}"', f"outputs = [{outs}]", ""]
            toml = os.path.join(d, name + ".toml")
            with open(toml, "w") as f:
                f.write("\n".join(lines))
            cases.append((name, toml, urdf, toml,
                          f"`{inner}` of the `example-robot-data` {ERD_VERSION} wheel (PyPI); "
                          f"its model file (written by the script: the URDF, `{flange}`'s pose "
                          f"as a task frame, the joints' home) is `build/erd/{name}.toml`; MuJoCo loads "
                          "the URDF without its `<visual>` and `<collision>` (meshes)",
                          mj_urdf, f"{os.path.basename(inner)} (example-robot-data)"))
    return cases


def check(name, toml, source, guess_toml, note, rbss, build, rng, mj_src=None):
    model_file = os.path.join(SRC, toml)  # an absolute toml stays itself
    peer_src = os.path.join(SRC, source if not source.endswith(".sdf") else "four_bar.xml")
    kind = "urdf" if source.endswith(".urdf") else "mjcf"
    rb = Rbss(rbss, build, model_file)
    guess = {**rb.home, **homes(guess_toml if os.path.isabs(guess_toml)
                                else os.path.join(SRC, guess_toml))}
    states, fres, iters = random_states(rb, guess, rng)
    ev = rb.eval(states)
    peers = {}
    mjp = MuJoCo(mj_src or peer_src)
    peers["MuJoCo"] = mjp
    peers["Pinocchio"] = Pinocchio(peer_src, kind, build, mjp)
    rows = []
    for pname, p in peers.items():
        names = p.names()
        missing = [c for c in names if c not in rb.coords]
        if missing:
            die(f"{name}: {pname}'s coordinates {missing} are not rbss's {rb.coords}")
        ri = [rb.coords.index(c) for c in names]        # rbss index of the peer's k-th name
        errs = {"M": 0.0, "bias": 0.0, "acc": 0.0}
        for s, e in zip(states, ev):
            X, Xd = np.array(s["X"]), np.array(s["Xdot"])
            tau_r = np.zeros(len(rb.coords))
            for a, u in zip(rb.actuated, s["U"]):
                tau_r[rb.coords.index(a)] = u   # gear 1 in these sources (U is the force)
            Mr, psi = np.array(e["M"]), np.array(e["psi"])
            Xdd = np.array(e["Xddot"])
            if pname == "MuJoCo":
                nv = p.m.nv
                q, v, tau = np.zeros(nv), np.zeros(nv), np.zeros(nv)
                for k, c in enumerate(names):
                    qa, va = p.joint[c]
                    q[qa], v[va], tau[va] = X[ri[k]], Xd[ri[k]], tau_r[ri[k]]
                order = [p.joint[c][1] for c in names]
                M = p.at(q, v, tau)
                bias = -p.d.qfrc_bias + p.d.qfrc_passive
                acc = p.constrained(tau)
            else:
                nv = p.model.nv
                q, v, tau = np.zeros(nv), np.zeros(nv), np.zeros(nv)
                for k, c in enumerate(names):
                    qa, va = p.index[c]
                    q[qa], v[va], tau[va] = X[ri[k]], Xd[ri[k]], tau_r[ri[k]]
                order = [p.index[c][1] for c in names]
                M, b = p.at(q, v)
                # Pinocchio's URDF damping is in model.damping, not in nle nor in its dynamics
                bias = -b - p.model.damping * v
                acc = p.constrained(q, v, tau - p.model.damping * v)
            o = np.array(order)
            errs["M"] = max(errs["M"], rel(Mr[np.ix_(ri, ri)], M[np.ix_(o, o)]))
            errs["bias"] = max(errs["bias"], rel(psi[ri], bias[o]))
            errs["acc"] = max(errs["acc"], rel(Xdd[ri], np.asarray(acc)[o]))
        rows.append((pname, len(names), errs))
    extra = [c for c in rb.coords if c not in peers["MuJoCo"].names()]
    return {"name": name, "toml": os.path.relpath(model_file, ROOT), "source": source, "peer_src": os.path.basename(peer_src),
            "n": len(rb.coords), "loops": len(mjp.points()), "extra": extra, "rows": rows,
            "note": note, "fres": fres, "iters": iters,
            "pin_notes": peers["Pinocchio"].notes}


def roundtrip(rbss, build):
    """Issue 21's "a URDF arm from import to `rbss roundtrip`": the one command, timed (cached
    library or not, as the cache has it)."""
    import time
    cmd = [rbss, "roundtrip", "--model-file", os.path.join(HERE, "import", "ur5_roundtrip.toml"),
           "--trajectory", os.path.join(ROOT, "models", "trajectories", "ur5.toml"),
           "--out", os.path.join(build, "roundtrip_ur5")]
    t0 = time.monotonic()
    out = run(cmd)
    dt = time.monotonic() - t0
    m = re.search(r"round-trip max output error: (\S+)", out)
    if not m:
        die(f"no round-trip error in:\n{out}")
    return float(m.group(1)), dt


def main():
    build, rbss, out = (os.path.abspath(a) for a in sys.argv[1:4])
    os.makedirs(build, exist_ok=True)
    # import.sh's defaults, for a direct run too: never a second cargo build directory
    os.environ.setdefault("RBSS_CACHE", os.path.join(build, "rbss-cache"))
    os.environ.setdefault("RBSS_CACHE_TARGET", os.path.join(ROOT, "target"))
    rng = np.random.default_rng(SEED)
    cases = CASES + ([] if os.environ.get("IMPORT_PUBLIC", "1") == "0" else external(build))
    results = []
    for c in cases:
        results.append(check(*c[:5], rbss, build, rng, *c[5:6]))
        if len(c) > 6:
            results[-1]["source"] = c[6]
    import mujoco
    import pinocchio as pin
    head = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    L = ["# Imported models against MuJoCo and Pinocchio (issue 21)", "",
         "Written by `bench/peers/import.sh` (do not edit): "
         f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, rbss {head}, "
         f"MuJoCo {mujoco.__version__}, Pinocchio {pin.__version__} (PyPI `pin`), "
         f"numpy {np.__version__}, Python {platform.python_version()}.", "",
         f"Each test source of `codegen/tests/import/` loaded by MuJoCo and by Pinocchio, and its "
         f"model file by `rbss eval --model-file` (the imported model, compiled and cached). "
         "Also two public robot descriptions, URDFs of the `example-robot-data` "
         f"{ERD_VERSION} wheel from PyPI (the UR5 of `ur_description` and Unitree's Z1 arm with "
         "its gripper joint, joint damping 1 to 2 N m s/rad), each with a model file the script "
         "writes (the URDF, the flange's pose as a task frame, the joints' home). "
         f"At {N_STATES} random states per model (seed {SEED}): every coordinate moved by up to 0.1 "
         "from the reference model's home, then Newton (min-norm steps on rbss's f and G) onto "
         "the loops (max |f| after, below); velocities random in G's null space; U uniform in "
         "[-10, 10] on the actuated coordinates (gear 1 in all these sources). Coordinates are matched by joint name. "
         "Relative error: max |rbss - peer| / max(1, max |peer|) over the matrix or vector, the "
         "largest over the states.", "",
         "- **M**: rbss's `M` against MuJoCo's `mj_fullM` and Pinocchio's `crba`;",
         "- **bias**: rbss's `psi` against `-qfrc_bias + qfrc_passive` (MuJoCo) and `-nle` "
         "(Pinocchio);",
         "- **accelerations**: rbss's forward dynamics (`Xddot` of `rbss eval` with `U`) against "
         "the constrained accelerations with the loops hard. MuJoCo's own constraints are soft "
         "(its impedance is at most 0.9999, 1e-4 off, see RESULT.md), so its hard solution is "
         "solved here from MuJoCo's pieces: `[M J'; J 0] [qacc; l] = [tau - qfrc_bias; "
         "-Jdot qvel]` with `mj_fullM`, `qfrc_bias`, `mj_jac` and `mj_jacDot` at the connect "
         "equalities' two points. Pinocchio: `constraintDynamics` with one `CONTACT_3D` "
         "(`LOCAL`) constraint per connect, its two points in the two joints' frames, no "
         "Baumgarte term, `ProximalSettings(1e-14, mu = 1e-9, 200)`. The open chains (the arms: "
         "their model files' task frame adds no mass) against "
         "MuJoCo's unconstrained `M^-1 (tau - bias)` and Pinocchio's `aba`. Joint damping: in "
         "MuJoCo's `qfrc_passive`; Pinocchio keeps the URDF's in `model.damping`, outside `nle` "
         "and `aba`, so `-damping v` is added to its bias and its `tau` (URDF `friction`, which "
         "rbss ignores with a warning, is MuJoCo's `frictionloss`, a constraint, not used "
         "here).", "",
         "| model file | source (peers load) | n (peers) | connects | peer | M | bias | accelerations |",
         "|---|---|---|---|---|---|---|---|"]
    worst = 0.0
    for r in results:
        for pname, npeer, e in r["rows"]:
            worst = max(worst, *e.values())
            if pname == "Pinocchio" and r["pin_notes"]:
                pname += "*"

            L.append(f"| `{r['toml']}` | `{r['source']}` (`{r['peer_src']}`) | {r['n']} ({npeer}) "
                     f"| {r['loops']} | {pname} | {e['M']:.1e} | {e['bias']:.1e} | {e['acc']:.1e} |")
    L += ["", f"Largest: {worst:.1e} (target <= 1e-12).", "", "Notes:", ""]
    for r in results:
        if r["extra"]:
            L.append(f"- `{r['toml']}`: rbss's coordinates {', '.join(r['extra'])} are its model "
                     "file's own (not in the source), left out of the comparison.")
        if r["note"]:
            L.append(f"- `{r['toml']}`: {r['note']}.")
        for n in r["pin_notes"]:
            L.append(f"- `{r['toml']}`, Pinocchio (marked *): {n}.")
        L.append(f"- `{r['toml']}`: states on the loops to max |f| = {r['fres']:.1e} "
                 f"({r['iters']} Newton steps).")
    L += ["- Pinocchio 4.1.0's MJCF parser reads only the first body under `<worldbody>` (the "
          "four-bar's rocker, five of the 6-UPS's legs and its platform would be lost): Pinocchio loads the source "
          "rewritten with the worldbody's bodies inside one body without joints at the world "
          "frame (the same mechanism), `<include>`s inlined by the script (`build/*.pin.xml`). It merges a body's several hinges into one composite "
          "joint (`Composite_phi1`), whose coordinates are matched to the body's joints in order. "
          "It ignores `<option gravity>`: its gravity is set to MuJoCo's.",
          "- MuJoCo loads the URDF through its own URDF compiler (`MjModel.from_xml_path`).", ""]
    rt_err, rt_time = roundtrip(rbss, build)
    L += ["## A URDF arm to `rbss roundtrip`", "",
          "Typed: one command, after writing the model file `bench/peers/import/ur5_roundtrip.toml` "
          "(8 lines besides comments: `urdf = ...`, rough homes of q2..q5 and the outputs, the task "
          "frame of the flange `tool0`) and with a "
          "trajectory of the outputs (`models/trajectories/ur5.toml`, 6 expressions):", "",
          "```sh",
          "rbss roundtrip --model-file bench/peers/import/ur5_roundtrip.toml \\",
          "  --trajectory models/trajectories/ur5.toml --out DIR",
          "```", "",
          f"This run: round-trip max output error {rt_err:.3e}, {rt_time:.2f} s (the first run "
          "after an edit generates and compiles the robot, about 13 s here). What the URDF cannot "
          "give is in the file's comment: the outputs (the task frame), a non-singular home (all "
          "joints at zero is the stretched arm: `rbss-codegen` refuses it), the trajectory.", ""]
    with open(out, "w") as f:
        f.write("\n".join(L))
    print("\n".join(L))
    return worst


if __name__ == "__main__":
    main()
