#!/usr/bin/env python3
"""Home (reference-assembly) values of the model files, and an independent check of them.

    python3 models/solve_homes.py          # print the closed-form homes
    python3 models/solve_homes.py --check  # load every models/*.toml, evaluate it, report f(home)

The check reads the model files themselves (parameters, coordinates, transforms, loops,
solids) with a small evaluator of its own, so it validates the files, not this script's
formulas. Standard library only (Python >= 3.11 for tomllib).
"""

import math
import pathlib
import re
import sys
import tomllib

DIGITS = 12  # significant digits written into the model files


def fmt(v):
    return f"{v:.{DIGITS}g}"


# --- 6-UPS Stewart platform (shared/paper-example.md) ---------------------------------------

R0, RP, H = 0.489, 0.389, 0.0
ALPHA = [-15, 15, 105, 135, 225, 255]
BETA = [-45, 45, 75, 165, 195, 285]
# Platform pose of TraekP at t = 0 (x = 0.1 cos 0, y = 0.1 sin 0, z = 0.94 (1 + 0), rotx = 0.1 cos 0,
# roty = 0.1 sin 0, rotz = 0.1 cos 0 sin 0).
POSE = dict(x=0.1, y=0.0, z=0.94, rotx=0.1, roty=0.0, rotz=0.0)


def rot(axis, a):
    c, s = math.cos(a), math.sin(a)
    if axis == "x":
        return [[1, 0, 0], [0, c, -s], [0, s, c]]
    if axis == "y":
        return [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    return [[c, -s, 0], [s, c, 0], [0, 0, 1]]


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def matvec(a, v):
    return [sum(a[i][k] * v[k] for k in range(3)) for i in range(3)]


def pose_frame(pose):
    """(R, p) of the paper's pose vector Tx(x) Ty(y) Tz(z) Rx(rotx) Ry(roty) Rz(rotz)."""
    R = matmul(matmul(rot("x", pose["rotx"]), rot("y", pose["roty"])), rot("z", pose["rotz"]))
    return R, [pose["x"], pose["y"], pose["z"]]


WORLD = ([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], [0.0, 0.0, 0.0])


def stewart_legs(base, r0, platform, rp, h=0.0):
    """Closed-form IK of the six legs of a 6-UPS stage whose base joints sit at
    base * Rz(alpha_i) Tx(r0) and platform joints at platform * Rz(beta_i) Tz(h) Tx(rp);
    base and platform are world frames (R, p). Returns d, phi, psi (six each)."""
    (Rb, pb), (Rp, pp) = base, platform
    d, phi, psi = [], [], []
    for a_deg, b_deg in zip(ALPHA, BETA):
        a, b = math.radians(a_deg), math.radians(b_deg)
        P = [pp[k] + matvec(Rp, [rp * math.cos(b), rp * math.sin(b), h])[k] for k in range(3)]
        B = [pb[k] + matvec(Rb, [r0 * math.cos(a), r0 * math.sin(a), 0.0])[k] for k in range(3)]
        w = [P[k] - B[k] for k in range(3)]
        di = math.sqrt(sum(x * x for x in w))
        # u = (Rb Rz(alpha))^T w / d = Rx(phi) Ry(psi) e_z
        #   = (sin psi, -sin phi cos psi, cos phi cos psi)
        u = matvec([list(r) for r in zip(*matmul(Rb, rot("z", a)))], w)
        u = [x / di for x in u]
        d.append(di)
        psi.append(math.asin(u[0]))
        phi.append(math.atan2(-u[1], u[2]))
    return d, phi, psi


def stewart_homes():
    return stewart_legs(WORLD, R0, pose_frame(POSE), RP, H)


# --- two 6-UPS stages in series (models/stewart_2stage.toml) ------------------------------------
# Stage 1 is the paper's robot at POSE; stage 2 is the same layout scaled by 0.6, its base
# joints on platform 1 (in platform 1's frame, h = 0), platform 2 0.56 m above platform 1 in the
# world with the same orientation (the bench's reference motion at t = 0).

R0_2, RP_2 = 0.29, 0.23
POSE_2 = dict(x=0.1, y=0.0, z=0.94 + 0.56, rotx=0.1, roty=0.0, rotz=0.0)


def stewart_2stage_homes():
    p1 = pose_frame(POSE)
    return stewart_legs(WORLD, R0, p1, RP, H), stewart_legs(p1, R0_2, pose_frame(POSE_2), RP_2)


# --- planar five-bar ----------------------------------------------------------------------------

B5, L1, L2 = 0.15, 0.2, 0.25
EFFECTOR = (0.0, 0.3)


def five_bar_homes():
    """Elbow-out: the left elbow left of the line base1 -> effector, the right one right of it."""
    out = {}
    for side, bx, sign in (("1", -B5, +1), ("2", B5, -1)):
        dx, dy = EFFECTOR[0] - bx, EFFECTOR[1]
        dist = math.hypot(dx, dy)
        # angle at the base between the base->effector line and the proximal link (law of cosines)
        gamma = math.acos((L1 * L1 + dist * dist - L2 * L2) / (2 * L1 * dist))
        th = math.atan2(dy, dx) + sign * gamma
        ex, ey = bx + L1 * math.cos(th), L1 * math.sin(th)
        a = math.atan2(EFFECTOR[1] - ey, EFFECTOR[0] - ex) - th
        a = math.atan2(math.sin(a), math.cos(a))
        out["th" + side], out["a" + side] = th, a
    out["x"], out["y"] = EFFECTOR
    return out


# --- independent check of the model files ---------------------------------------------------


def evaluate(expr, env):
    if isinstance(expr, (int, float)):
        return float(expr)
    text = expr.replace("^", "**")
    if not re.fullmatch(r"[A-Za-z0-9_+\-*/(). ,eE]*", text):
        raise ValueError(f"unexpected characters in {expr!r}")
    names = dict(env, pi=math.pi, sin=math.sin, cos=math.cos, tan=math.tan, sqrt=math.sqrt)
    return float(eval(text, {"__builtins__": {}}, names))


def expand_steps(steps):
    out = []
    for s in steps:
        if isinstance(s, list):
            elems = [("T", "x"), ("T", "y"), ("T", "z"), ("R", "x"), ("R", "y"), ("R", "z")]
            slots = [None] * 6
            for k in range(6):
                slots[s[6 + k] - 1] = (elems[k][0], elems[k][1], s[k])
            out.extend(slots)
        else:
            m = re.fullmatch(r"\s*([RT])([xyz])\((.*)\)\s*", s)
            out.append((m.group(1), m.group(2), m.group(3)))
    return out


def apply(frame, steps, env):
    R, p = frame
    for kind, axis, e in expand_steps(steps):
        v = evaluate(e, env)
        if kind == "R":
            R = matmul(R, rot(axis, v))
        else:
            local = [v if axis == ax else 0.0 for ax in "xyz"]
            p = [p[k] + matvec(R, local)[k] for k in range(3)]
    return R, p


def check(path):
    model = tomllib.loads(pathlib.Path(path).read_text())
    env = {}
    for name, spec in model.get("parameters", {}).items():
        if isinstance(spec, dict):
            v = evaluate(spec["value"], env)
            if spec.get("unit") == "deg":
                v = math.radians(v)
        else:
            v = evaluate(spec, env)
        env[name] = v
    for c in model["coordinates"]:
        h = evaluate(c.get("home", 0), env)
        env[c["name"]] = math.radians(h) if c["unit"] == "deg" else h
    ident = ([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], [0.0, 0.0, 0.0])
    frames = {"world": ident}
    for body in model["body"]:
        frames[body["name"]] = apply(frames[body.get("parent", "world")], body.get("transforms", []), env)
        solid = body.get("solid")
        if solid:
            if "mass" in solid:
                m = evaluate(solid["mass"], env)
            elif solid["shape"] == "cylinder":
                r, L = evaluate(solid["radius"], env), evaluate(solid["length"], env)
                m = evaluate(solid["density"], env) * math.pi * r * r * L
            else:
                a, b, c = (evaluate(x, env) for x in solid["size"])
                m = evaluate(solid["density"], env) * a * b * c
            print(f"  {body['name']:>12}: mass {m:.12f} kg")
    worst = 0.0
    for lp in model["loop"]:
        pa = apply(frames[lp["a"]["body"]], lp["a"].get("transforms", []), env)[1]
        pb = apply(frames[lp["b"]["body"]], lp["b"].get("transforms", []), env)[1]
        for comp in lp.get("components", ["x", "y", "z"]):
            k = "xyz".index(comp)
            worst = max(worst, abs(pa[k] - pb[k]))
    print(f"  {path}: max |f(home)| = {worst:.3e}")
    return worst


def main():
    if "--check" in sys.argv:
        here = pathlib.Path(__file__).parent
        worst = max(check(p) for p in sorted(here.glob("*.toml")))
        sys.exit(0 if worst < 1e-9 else 1)
    d, phi, psi = stewart_homes()
    print("stewart_6ups, platform pose", POSE)
    for i in range(6):
        print(f"  leg {i + 1}: d = {fmt(d[i])}, phi = {fmt(phi[i])}, psi = {fmt(psi[i])}")
    (d1, phi1, psi1), (d2, phi2, psi2) = stewart_2stage_homes()
    print("stewart_2stage, platform poses", POSE, POSE_2)
    for i in range(6):
        print(f"  leg {i + 1}: d = {fmt(d1[i])}, phi = {fmt(phi1[i])}, psi = {fmt(psi1[i])}")
    for i in range(6):
        print(f"  leg {i + 7}: d = {fmt(d2[i])}, phi = {fmt(phi2[i])}, psi = {fmt(psi2[i])}")
    print("five_bar, effector at", EFFECTOR)
    for k, v in five_bar_homes().items():
        print(f"  {k} = {fmt(v)}")


if __name__ == "__main__":
    main()
