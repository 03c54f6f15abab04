"""Glue for bench/peers/run.sh (standard library only; run with the venv's python).

  peers.py states  BUILD RBSS   -> BUILD/states.txt (+ BUILD/timing_state.txt), from rbss's CLI
  peers.py report  BUILD OUTDIR -> OUTDIR/RESULT.md, OUTDIR/peers.csv

States (the agreement checks): the paper's TraekP at t = 0, 0.1, ..., 2 s (`rbss paper
--samples 21`: inverse kinematics X, Xdot, Xddot and inverse dynamics U, lambda), with M and f
from `rbss eval`. Timing state: the state of `rbss bench solvers` (src/solver_table.rs: home
outputs + 1e-3 alternating, output rates 0.1 alternating), rebuilt with `rbss ik`, the velocity
solve on G from `rbss eval`, and U from `rbss inverse-dynamics --trajectory` (a polynomial with
those values at t = 0).
"""

import csv
import datetime
import json
import math
import os
import platform
import shutil
import subprocess
import sys

N, M = 24, 18
NAMES = ([f"d{i}" for i in range(1, 7)] + [f"phi{i}" for i in range(1, 7)]
         + [f"psi{i}" for i in range(1, 7)] + ["x", "y", "z", "rotx", "roty", "rotz"])


def die(msg):
    sys.exit(f"bench/peers: ERROR: {msg}")


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        die(f"`{' '.join(cmd)}` failed ({r.returncode}):\n{r.stderr}{r.stdout}")
    return r.stdout


def read_csv(path):
    with open(path) as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    head = rows[0]
    return [dict(zip(head, map(float, r))) for r in rows[1:]]


def rbss_eval(rbss, build, states, tag):
    path = os.path.join(build, f"eval_{tag}.json")
    with open(path, "w") as f:
        json.dump({"states": states}, f)
    out = json.loads(run([rbss, "eval", "--model", "stewart_6ups", "--states", path]))
    return out["states"]


def solve(a, b):
    """Gaussian elimination with partial pivoting (small dense systems)."""
    n = len(a)
    m = [row[:] + [b[i]] for i, row in enumerate(a)]
    for c in range(n):
        p = max(range(c, n), key=lambda r: abs(m[r][c]))
        m[c], m[p] = m[p], m[c]
        for r in range(c + 1, n):
            k = m[r][c] / m[c][c]
            for j in range(c, n + 1):
                m[r][j] -= k * m[c][j]
    x = [0.0] * n
    for r in reversed(range(n)):
        x[r] = (m[r][n] - sum(m[r][j] * x[j] for j in range(r + 1, n))) / m[r][r]
    return x


def states(build, rbss):
    # 1. TraekP: inverse kinematics and inverse dynamics at 21 samples.
    paper = os.path.join(build, "rbss_paper")
    run([rbss, "paper", "--out", paper, "--samples", "21"])
    ik = read_csv(os.path.join(paper, "inverse_kinematics.csv"))
    idy = read_csv(os.path.join(paper, "inverse_dynamics.csv"))
    if len(ik) != 21 or len(idy) != 21:
        die(f"expected 21 samples from rbss paper, got {len(ik)} / {len(idy)}")
    sts = []
    for a, b in zip(ik, idy):
        if abs(a["t"] - b["t"]) > 1e-12:
            die("rbss paper: kinematics and dynamics samples at different times")
        sts.append({
            "t": a["t"],
            "X": [a[n] for n in NAMES],
            "Xdot": [a[n + "_dot"] for n in NAMES],
            "Xddot": [a[n + "_ddot"] for n in NAMES],
            "U": [b[f"U{i}"] for i in range(1, 7)],
            "lambda": [b[f"lambda{i}"] for i in range(1, 19)],
        })
    ev = rbss_eval(rbss, build, [{"X": s["X"], "Xdot": s["Xdot"]} for s in sts], "traek_p")

    # 2. The state of `rbss bench solvers` (src/solver_table.rs, `state` and `measure`).
    home = [0.1, 0.0, 0.94, 0.1, 0.0, 0.0]   # models/stewart_6ups.toml, the outputs' home
    sign = lambda i: 1.0 if i % 2 == 0 else -1.0
    o1 = [v + 1e-3 * sign(i) for i, v in enumerate(home)]
    odot = [0.1 * sign(i + 1) for i in range(6)]
    oddot = [0.5 * sign(i) * (1 + i / 10) for i in range(6)]
    out = run([rbss, "ik", "--model", "stewart_6ups", "--pose", ",".join(repr(v) for v in o1)])
    xb = {}
    for line in out.splitlines():
        p = line.split()
        if len(p) >= 3 and p[1] == "=" and p[0] in NAMES:
            xb[p[0]] = float(p[2])
    if len(xb) != N:
        die(f"could not parse `rbss ik` output:\n{out}")
    X = [xb[n] for n in NAMES]
    g = rbss_eval(rbss, build, [{"X": X, "Xdot": [0.0] * N}], "bench_g")[0]["G"]
    # G Xdot = 0 with the platform rates given: G[:, legs] Xdot_legs = -G[:, platform] odot
    a = [[g[r][c] for c in range(18)] for r in range(M)]
    b = [-sum(g[r][18 + j] * odot[j] for j in range(6)) for r in range(M)]
    Xdot = solve(a, b) + odot
    names = ["x", "y", "z", "rotx", "roty", "rotz"]
    toml = os.path.join(build, "bench_state.toml")
    with open(toml, "w") as f:
        f.write("# the state of `rbss bench solvers` at t = 0 (src/solver_table.rs)\n")
        for n, p, v, acc in zip(names, o1, odot, oddot):
            f.write(f'{n} = "{p!r} + ({v!r})*t + ({acc / 2!r})*t^2"\n')
    ucsv = os.path.join(build, "bench_state_u.csv")
    run([rbss, "inverse-dynamics", "--model", "stewart_6ups", "--trajectory", toml,
         "--t-end", "1", "--samples", "2", "--csv", ucsv])
    u = read_csv(ucsv)[0]
    eb = rbss_eval(rbss, build, [{"X": X, "Xdot": Xdot}], "bench")[0]
    bench = {"t": -1.0, "X": X, "Xdot": Xdot, "Xddot": [0.0] * N,
             "U": [u[f"U{i}"] for i in range(1, 7)],
             "lambda": [u[f"lambda{i}"] for i in range(1, 19)]}

    with open(os.path.join(build, "states.txt"), "w") as f:
        allst = sts + [bench]
        alle = ev + [eb]
        f.write(f"{len(allst)}\n")
        for s, e in zip(allst, alle):
            nums = ([s["t"]] + s["X"] + s["Xdot"] + s["Xddot"] + s["U"] + s["lambda"]
                    + [v for row in e["M"] for v in row] + e["f"])
            f.write(" ".join(repr(float(v)) for v in nums) + "\n")
    with open(os.path.join(build, "timing_state.txt"), "w") as f:
        f.write(f"{len(sts)}\n")   # index of the bench state in states.txt
    print(f"states: {len(sts)} on TraekP + the `rbss bench solvers` state", file=sys.stderr)


def parse_results(path):
    res = {"state": [], "time": {}}
    cur = None
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] == "state":
                cur = {"k": int(p[1]), "t": float(p[3])}
                res["state"].append(cur)
            elif p[0] in ("pin", "mj"):
                d = {p[i]: float(p[i + 1]) for i in range(2, len(p) - 1, 2)}
                cur[p[0]] = d
            elif p[0] == "rbss_constraint":
                cur["rbss_f"], cur["rbss_ke"] = float(p[1]), float(p[3])
            elif p[0] == "lcaba":
                res.setdefault("lcaba", {})[int(p[1])] = {"fd_acc_rel": float(p[3]), "iter": int(p[5]),
                                                          "residual": float(p[7])}
            elif p[0] == "mj_solimp":
                res.setdefault("solimp", []).append((float(p[2]), float(p[4]), float(p[6])))
            elif p[0] == "time":
                res["time"][p[1]] = float(p[2])
            else:
                res[p[0]] = " ".join(p[1:])
    return res


def fmt_ns(ns):
    return f"{ns / 1000:.2f} µs" if ns >= 1000 else f"{ns:.0f} ns"


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def report(build, outdir):
    r = parse_results(os.path.join(build, "results.txt"))
    rbss = sys.argv[4] if len(sys.argv) > 4 else os.path.join(ROOT, "target", "release", "rbss")
    r["rbss_binary"] = rbss
    r["rbss_mtime"] = datetime.datetime.fromtimestamp(os.path.getmtime(rbss), datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    rows = read_csv_str(os.path.join(build, "rbss_bench", "solvers.csv"))
    fd = [row for row in rows if row["solver"] == "forward_dynamics"]
    if not fd:
        die("no forward_dynamics row in rbss bench solvers' CSV")
    rbss_fd = float(fd[0]["ns_per_call"])
    rbss_id = [float(row["ns_per_call"]) for row in rows if row["solver"] == "inverse_dynamics"]
    t = r["time"]
    ti = int(r["timing_state"].split()[0])
    traek = [s for s in r["state"] if s["k"] != ti]
    bench = [s for s in r["state"] if s["k"] == ti][0]

    calls = [
        ("rbss", "forward_dynamics (Model/Data preallocated; `rbss bench solvers`)", rbss_fd, True),
        ("Pinocchio", "constraintDynamics, Data and constraint datas preallocated, initConstraintDynamics excluded",
         t["pin_constraintDynamics"], True),
        ("Pinocchio", "initConstraintDynamics + constraintDynamics (Data preallocated)",
         t["pin_init_plus_constraintDynamics"], True),
        ("Pinocchio", "fresh Data + constraint datas + initConstraintDynamics + constraintDynamics",
         t["pin_fresh_data_init_constraintDynamics"], True),
        ("MuJoCo", "mj_forward (soft `connect` constraints, Newton solver, tolerance 1e-10, dense Jacobian)",
         t["mj_forward"], True),
        ("Pinocchio", f"(info) lcaba, closed-loop constrained ABA (proximal, mu = {r['lcaba_settings'].split()[1]}, "
                      f"{r.get('lcaba_timing_iter', '?')} iterations here)", t["pin_lcaba"], False),
        ("Pinocchio", "(info) initConstraintDynamics alone", t["pin_initConstraintDynamics"], False),
        ("Pinocchio", "(info) crba (mass matrix)", t["pin_crba"], False),
        ("Pinocchio", "(info) rnea (inverse dynamics of the open tree)", t["pin_rnea"], False),
        ("MuJoCo", "(info) mj_fwdPosition (kinematics, inertia, factorisation, constraint rows)",
         t["mj_fwdPosition"], False),
        ("MuJoCo", "(info) mj_fwdVelocity (velocities, bias forces)", t["mj_fwdVelocity"], False),
        ("MuJoCo", "(info) mj_fwdActuation", t["mj_fwdActuation"], False),
        ("MuJoCo", "(info) mj_fwdAcceleration (unconstrained qacc)", t["mj_fwdAcceleration"], False),
        ("MuJoCo", "(info) mj_fwdConstraint (constraint solver)", t["mj_fwdConstraint"], False),
        ("MuJoCo", "(info) mj_crb + mj_factorM (inside mj_fwdPosition)", t["mj_crb_factorM"], False),
    ]
    if rbss_id:
        calls.insert(1, ("rbss", "(info) inverse_dynamics (`rbss bench solvers`)", rbss_id[0], False))

    with open(os.path.join(outdir, "peers.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["library", "call", "median_ns_per_call", "ratio_to_rbss_forward_dynamics"])
        for lib, call, ns, _ in calls:
            w.writerow([lib, call, f"{ns:.1f}", f"{ns / rbss_fd:.3f}"])

    def mx(lib, key, states=traek):
        return max(s[lib][key] for s in states)

    nproc = os.cpu_count()
    load = open("/proc/loadavg").read().split()[:3] if os.path.exists("/proc/loadavg") else ["?"] * 3
    rustc = run(["rustc", "--version"]).strip() if shutil.which("rustc") else "unknown"
    gxx = run(["g++", "--version"]).splitlines()[0] if shutil.which("g++") else "unknown"
    L = []
    L.append("# rbss beside Pinocchio and MuJoCo: the paper's 6-UPS\n")
    L.append("Written by `bench/peers/run.sh` (see README.md); do not edit by hand.\n")
    L.append("## Forward dynamics, median time per call\n")
    L.append(f"All at the state of `rbss bench solvers` (home outputs + 1e-3, output rates ±0.1, "
             f"`U` its inverse dynamics), measured back to back in one run of the script: the "
             f"C++ harness first, `rbss bench solvers --model stewart_6ups` right after. Ratio = "
             f"time / rbss `forward_dynamics` ({fmt_ns(rbss_fd)}).\n")
    L.append("| library | call | median | ratio to rbss forward_dynamics |")
    L.append("|---|---|---:|---:|")
    for lib, call, ns, _ in calls:
        L.append(f"| {lib} | {call} | {fmt_ns(ns)} | {ns / rbss_fd:.2f}× |")
    L.append("")
    L.append(f"MuJoCo's constraint solver took {r.get('mj_solver_iterations', '?')} Newton "
             f"iteration(s) at this state. Harness timing: `std::chrono::steady_clock`, batches of "
             f"200 to 5000 calls after a warm-up batch, median over 201 batches of the time per "
             f"call; no pinning. rbss: its own harness (`src/solver_table.rs`: ~1 ms batches, "
             f"median). The machine is shared (load average below); on it, reruns differ by "
             f"about ±5 % for these µs-scale figures.\n")

    L.append("## Agreement with rbss\n")
    L.append(f"{len(traek)} states on the paper's TraekP (t = 0, 0.1, ..., 2 s): `X, Xdot, Xddot` "
             f"from rbss's inverse kinematics and `U, lambda` from its inverse dynamics "
             f"(`rbss paper --samples 21`), `M` and `f` from `rbss eval`; mapped into each library's "
             f"coordinates (platform quaternion, body-frame angular velocity; Pinocchio's "
             f"free-flyer velocity is the body twist, MuJoCo's linear velocity is in the world "
             f"frame). Max over the states of the relative difference "
             f"(max |lib - rbss| / max |rbss| over the vector or matrix):\n")
    L.append("| check | Pinocchio | MuJoCo |")
    L.append("|---|---:|---:|")
    rowsd = [
        ("kinetic energy ½ Ẋᵀ M Ẋ (Pinocchio `computeKineticEnergy`, MuJoCo ½ qvelᵀ M qvel)", "ke_rel"),
        ("mass matrix: rbss M vs Tᵀ M_lib T, T = ∂v/∂Ẋ the library's velocity in rbss's rates (all 24 × 24 entries)", "M_rel"),
        ("inverse dynamics: actuator forces U (library RNEA + its Jacobian of f, solved for U, λ)", "U_rel"),
        ("inverse dynamics: multipliers λ (same solve)", "lambda_rel"),
        ("forward dynamics with rbss's U: accelerations (mapped Ẍ)", "fd_acc_rel"),
        ("forward dynamics with rbss's U: multipliers λ", "fd_lambda_rel"),
    ]
    for label, key in rowsd:
        L.append(f"| {label} | {mx('pin', key):.1e} | {mx('mj', key):.1e} |")
    lc = [v for k, v in r.get("lcaba", {}).items() if k != ti]
    if lc:
        lo, hi = min(v["iter"] for v in lc), max(v["iter"] for v in lc)
        iters = f"{lo}" if lo == hi else f"{lo} to {hi}"
        L.append(f"| forward dynamics, Pinocchio `lcaba` (mu = {r['lcaba_settings'].split()[1]}, "
                 f"{iters} iterations): accelerations | "
                 f"{max(v['fd_acc_rel'] for v in lc):.1e} | |")
    L.append(f"| loop closure max \\|f\\| in the library at rbss's X [m] (rbss's own: "
             f"{max(s['rbss_f'] for s in traek):.1e}) | {mx('pin', 'f'):.1e} | {mx('mj', 'f'):.1e} |")
    L.append(f"| velocity constraint max \\|G v\\| [m/s] | {mx('pin', 'Gv'):.1e} | {mx('mj', 'Gv'):.1e} |")
    L.append(f"| residual of the 24 × 24 inverse-dynamics solve | {mx('pin', 'id_resid'):.1e} | "
             f"{mx('mj', 'id_resid'):.1e} |")
    L.append("")
    L.append(f"At the timing state (off TraekP; only the velocity-level checks apply): kinetic "
             f"energy {bench['pin']['ke_rel']:.1e} (Pinocchio), {bench['mj']['ke_rel']:.1e} "
             f"(MuJoCo); mass matrix {bench['pin']['M_rel']:.1e}, {bench['mj']['M_rel']:.1e}.\n")
    L.append("Per state (TraekP):\n")
    L.append("| t [s] | T rbss [J] | T Pin. rel | T MuJoCo rel | U Pin. rel | U MuJoCo rel | Ẍ Pin. FD rel | q̈ MuJoCo FD rel |")
    L.append("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for s in traek:
        L.append(f"| {s['t']:.1f} | {s['rbss_ke']:.6f} | {s['pin']['ke_rel']:.1e} | {s['mj']['ke_rel']:.1e} "
                 f"| {s['pin']['U_rel']:.1e} | {s['mj']['U_rel']:.1e} | {s['pin']['fd_acc_rel']:.1e} "
                 f"| {s['mj']['fd_acc_rel']:.1e} |")
    L.append("")
    L.append(NOTES)
    if r.get("solimp"):
        L.append("MuJoCo's forward-dynamics error against its impedance `d` (`solimp = d d ...`), "
                 f"at t = {r['solimp'][0][0]:.1f} s, measured in this run: "
                 + ", ".join(f"d = {d:g}: {e:.1e}" for _, d, e in r["solimp"])
                 + ". It falls as (1 - d)/d, the regularisation, and stops at MuJoCo's bound.\n")
    L.append("## Versions and machine\n")
    L.append("| | |")
    L.append("|---|---|")
    L.append(f"| Pinocchio | {r['pinocchio_version']} (PyPI `pin`/`libpinocchio` wheel; its headers compiled into the harness, `libpinocchio_default.so`) |")
    L.append(f"| MuJoCo | {r['mujoco_version']} (PyPI `mujoco-core` wheel: `libmujoco.so` + headers) |")
    L.append(f"| Eigen | {r['eigen_version']} (PyPI `cmeel-eigen`) |")
    L.append(f"| C++ | {gxx}, `-O3 -DNDEBUG`, no `-march` (like rbss: no `target-cpu`) |")
    L.append(f"| rbss | `{os.path.relpath(r.get('rbss_binary', 'target/release/rbss'), ROOT)}` built {r.get('rbss_mtime', '?')} "
             f"from a working tree at commit {git_head()} ({rustc}) |")
    L.append(f"| date | {datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')} |")
    L.append(f"| machine | nproc = {nproc}, CPU `{cpu_model()}`, load average at the end {' '.join(load)} |")
    L.append(f"| masses [kg] | lower link, upper link, platform: {r['masses']} (paper-example.md: 30.630528372500, 31.365661053441, 74.160674941682) |")
    L.append("")
    with open(os.path.join(outdir, "RESULT.md"), "w") as f:
        f.write("\n".join(L) + "\n")
    print("\n".join(L[4:4 + len(calls) + 3]))


ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def git_head():
    r = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    if r.returncode != 0:
        return "unknown"
    d = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"],
                       capture_output=True, text=True)
    return r.stdout.strip() + (" with uncommitted changes" if d.stdout.strip() else "")


def read_csv_str(path):
    with open(path) as f:
        return list(csv.DictReader(f))


NOTES = """### How the models are built, and what does not agree exactly

- **Same robot.** Every number from `shared/paper-example.md`: base joints `Rz(alpha_i) Tx(r0)`,
  universal joint `Rx(phi_i) Ry(psi_i)`, prismatic `Tz(d_i)`, platform `Tx Ty Tz Rx Ry Rz`,
  platform joints `Rz(beta_i) Tz(h) Tx(rp)`; solid steel cylinders (masses, centres of mass,
  inertias about the centre of mass in the body axes), gravity `(0, 0, -9.81)`, no friction,
  armature or damping. The actuated forces `U_i` act on the prismatic coordinates `d_i`.
- **Pinocchio**: a tree from the world: the platform on a free-flyer joint, and per leg
  `RX -> RY -> PZ` (the lower link's inertia on `RY`, the upper link's on `PZ`, the `RX` body
  massless); six `RigidConstraintModel(CONTACT_3D, LOCAL)` between the `PZ` joint origin (`P_i` on
  the leg) and `P_i` on the platform, Baumgarte gains 0, `constraintDynamics` with the default
  `ProximalSettings` (mu = 0, one iteration: an exact Cholesky solve). Its multipliers
  `lambda_c` are the force on the leg side in the leg's contact frame: rbss's `lambda = -R lambda_c`.
- **Pinocchio `lcaba`** (for information; the brief's peer is `constraintDynamics`): the
  closed-loop constrained ABA of `loop-constrained-aba.hpp` on the same model and constraint
  models, after `computeJointMinimalOrdering`; an augmented-Lagrangian iteration whose accuracy
  depends on `mu`: with mu = 1e-6, 3 iterations, ~1e-10; mu = 1e-4 reached ~1e-12 in 6 iterations
  at 1.5x the time; mu <= 1e-10 loses accuracy (1e-7 and worse), by a one-off sweep.
- **MuJoCo**: the same bodies in MJCF (`build/stewart_6ups.xml`), hinge x, hinge y and slide z
  joints, explicit `<inertial>`, six `<connect site1 site2>` equality constraints; `mj_forward`
  with `qfrc_applied = S U`.
- **Inverse dynamics in the libraries** is the library's own RNEA (`pinocchio::rnea`, `mj_rne`
  with the acceleration) and its own kinematic Jacobian of the loop closure (world-frame point
  Jacobians: `getFrameJacobian(LOCAL_WORLD_ALIGNED)`, `mj_jacSite`), solved for `[U; lambda]` in
  `tau = S U - G^T lambda` (rbss's sign, design.md). Neither library has an inverse-dynamics call
  for closed loops that returns actuator forces, so this is the comparison of their dynamics
  (M, bias forces, gravity, Jacobians) with rbss's at the same motion.
- **MuJoCo's forward dynamics cannot agree to 1e-9**: its equality constraints are soft by
  design. The constraint force solves a regularised problem with `R = (1 - d)/d * diag(A)`, and
  the impedance `d` is clamped to at most `mjMAXIMP = 0.9999` (here `solimp = 0.9999 0.9999`,
  the hardest allowed), so the constraint accelerations are off by about 1e-4 of the constraint
  forces' effect: the "forward dynamics" rows of the MuJoCo column measure that regularisation,
  not a modelling difference (the inverse-dynamics and mass-matrix rows show the model agrees).
  The reference acceleration `aref = -b v - k r` is negligible here (`r`, `v` ~ 1e-12).
- The Euler-angle map (rbss `rotx, roty, rotz` -> quaternion, body angular velocity and its
  derivative) is written out in `harness.cpp` (`platform_kin`); the rbss side is used as given.
"""


if __name__ == "__main__":
    if len(sys.argv) not in (4, 5) or sys.argv[1] not in ("states", "report"):
        die("usage: peers.py states BUILD RBSS | peers.py report BUILD OUTDIR [RBSS]")
    if sys.argv[1] == "states":
        states(sys.argv[2], sys.argv[3])
    else:
        report(sys.argv[2], sys.argv[3])
