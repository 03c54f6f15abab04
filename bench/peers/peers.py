"""Glue for bench/peers/run.sh (standard library only; run with the venv's python).

  peers.py states  BUILD RBSS   -> BUILD/states.txt (+ BUILD/timing_state.txt), from rbss's CLI
  peers.py report  BUILD OUTDIR [RBSS [RBSS_NATIVE]] -> OUTDIR/RESULT.md, OUTDIR/peers.csv
                                  (+ BUILD/codegen/results.txt, the generated-code peer, when run;
                                  + BUILD/rbss_bench_native/, the native rbss, when RBSS_NATIVE)

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
import re
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


def parse_codegen(build):
    """BUILD/codegen/results.txt (codegen_harness.cpp) + gen_info.txt (codegen_gen.cpp, run.sh),
    or None when this run did not include the generated-code peer (PEERS_CODEGEN=0)."""
    cg = os.path.join(build, "codegen")
    path = os.path.join(cg, "results.txt")
    if not os.path.exists(path):
        return None
    res = {"state": [], "time": {}, "info": {}}
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] == "cg":
                d = {p[i]: float(p[i + 1]) for i in range(6, len(p) - 1, 2)}
                d.update(k=int(p[1]), build=p[3], t=float(p[5]))
                res["state"].append(d)
            elif p[0] == "time":
                res["time"][p[1]] = float(p[2])
            else:
                res[p[0]] = p[1:]
    with open(os.path.join(cg, "gen_info.txt")) as f:
        for line in f:
            k, _, v = line.strip().partition(" ")
            res["info"][k] = v
    src = os.path.join(cg, "src", "constraintDynamics_forward_zero.c")
    with open(src) as f:
        text = f.read()
    res["c_lines"] = text.count("\n")
    res["c_assign"] = sum(1 for line in text.splitlines() if line.strip().startswith(("v[", "y[")))
    m = re.search(r"double v\[(\d+)\];", text)
    res["c_aux"] = int(m.group(1)) if m else 0
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
    rbss_fd, rbss_id, rbss_rounds = bench_rows(os.path.join(build, "rbss_bench"))
    native = None   # the rbss built with target-cpu=native (RBSS_NATIVE), when run
    if len(sys.argv) > 5:
        nbin = sys.argv[5]
        nfd, nid, nrounds = bench_rows(os.path.join(build, "rbss_bench_native"))
        native = {"binary": nbin, "fd": nfd, "id": nid, "rounds": nrounds, "cpu": rustc_native_cpu(),
                  "mtime": datetime.datetime.fromtimestamp(os.path.getmtime(nbin), datetime.timezone.utc)
                  .strftime("%Y-%m-%d %H:%M UTC")}
    # the ratio's reference per build class: portable peers over the portable rbss, native peers
    # over the native rbss (over the portable one when no native rbss was run)
    ref = {"portable": rbss_fd, "native": native["fd"] if native else rbss_fd}
    ref_name = {"portable": "portable", "native": "native" if native else "portable"}
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
    cg = parse_codegen(build)
    if cg:
        ct = cg["time"]
        calls[2:2] = [
            ("Pinocchio", "generated constraintDynamics (CppADCodeGen straight-line C, gcc -O3, no -march; "
                          "see the section below)", ct["cg_constraintDynamics_portable"], True),
            ("Pinocchio", f"generated constraintDynamics, the same C with gcc -O3 -march=native "
                          f"({cg['info'].get('cg_native_march', '?')})", ct["cg_constraintDynamics_native"], True),
        ]
    calls = [c + ("portable",) for c in calls]
    if cg:
        calls[3] = calls[3][:4] + ("native",)
    head = []
    if rbss_id is not None:
        head.append(("rbss", "(info) inverse_dynamics (`rbss bench solvers`)", rbss_id, False, "portable"))
    if native:
        head.append(("rbss", f"forward_dynamics, built with `target-cpu=native` ({native['cpu']})",
                     native["fd"], True, "native"))
        if native["id"] is not None:
            head.append(("rbss", "(info) inverse_dynamics, built with `target-cpu=native`",
                         native["id"], False, "native"))
    calls[1:1] = head

    with open(os.path.join(outdir, "peers.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["library", "call", "build", "median_ns_per_call", "ratio_to_rbss_forward_dynamics",
                    "rbss_build_of_the_ratio"])
        for lib, call, ns, _, b in calls:
            w.writerow([lib, call, b, f"{ns:.1f}", f"{ns / ref[b]:.3f}", ref_name[b]])

    def mx(lib, key, states=traek):
        return max(s[lib][key] for s in states)

    nproc = os.cpu_count()
    # run.sh's timing window: "start|end YYYY-MM-DD HH:MM:SS load1 load5 load15"
    win = {}
    wp = os.path.join(build, "timing_window.txt")
    if os.path.exists(wp):
        for line in open(wp):
            p = line.split()
            if len(p) == 6:
                win[p[0]] = (f"{p[1]} {p[2][:5]} UTC", p[3:6])
    if "start" not in win or "end" not in win:
        die(f"{wp}: no start and end of the timing window (run.sh writes it)")
    rustc = run(["rustc", "--version"]).strip() if shutil.which("rustc") else "unknown"
    gxx = run(["g++", "--version"]).splitlines()[0] if shutil.which("g++") else "unknown"
    L = []
    L.append("# rbss beside Pinocchio and MuJoCo: the paper's 6-UPS\n")
    L.append("Written by `bench/peers/run.sh` (see README.md); do not edit by hand.\n")
    L.append("## Forward dynamics, median time per call\n")
    L.append(f"All at the state of `rbss bench solvers` (home outputs + 1e-3, output rates ±0.1, "
             f"`U` its inverse dynamics), measured back to back in one run of the script: the "
             f"C++ harness first{', the generated-code harness next' if cg else ''}, "
             f"`rbss bench solvers --model stewart_6ups` right after"
             f"{' (the portable rbss, then the one built with `target-cpu=native`)' if native else ''}. "
             f"Ratio = time / rbss `forward_dynamics` of the same build class: portable rows over "
             f"the portable rbss ({fmt_ns(rbss_fd)}), native rows over "
             + (f"the native rbss ({fmt_ns(native['fd'])})" if native else
                f"the portable rbss too (no native rbss in this run: `RBSS_NATIVE` unset)")
             + ". Portable: rbss without `target-cpu`, C and C++ `-O3` without `-march`; native: rbss "
             "with `RUSTFLAGS=\"-C target-cpu=native\"`, the generated C with `-march=native`"
             + (f" (rustc's `native` is {native['cpu']}, gcc's is {cg['info'].get('cg_native_march', '?')}"
                + (": this gcc does not know the newer name; it tunes for the older CPU and enables "
                   "the instruction sets the host reports" if native["cpu"] != cg["info"].get("cg_native_march")
                   else "")
                + ")" if native and cg else "")
             + ".\n")
    L.append("| library | call | build | median | ratio to rbss forward_dynamics, same build |")
    L.append("|---|---|---|---:|---:|")
    for lib, call, ns, _, b in calls:
        L.append(f"| {lib} | {call} | {b} | {fmt_ns(ns)} | {ns / ref[b]:.2f}× |")
    L.append("")
    L.extend(targets_section(t, cg, rbss_fd, native))
    L.append(f"MuJoCo's constraint solver took {r.get('mj_solver_iterations', '?')} Newton "
             f"iteration(s) at this state. Harness timing: `std::chrono::steady_clock`, batches of "
             f"200 to 5000 calls after a warm-up batch, median over 201 batches of the time per "
             f"call; no pinning. rbss: its own harness (`src/solver_table.rs`: ~1 ms batches, "
             f"median), three rounds of `rbss bench solvers` per binary, alternating, the median "
             f"round reported (forward_dynamics' rounds: portable "
             f"{', '.join(fmt_ns(x) for x in rbss_rounds)}"
             + (f"; native {', '.join(fmt_ns(x) for x in native['rounds'])}" if native else "")
             + "). The machine is shared (load average below); on it, reruns differ by "
             f"about ±5 % for these µs-scale figures.\n")

    if cg:
        L.extend(codegen_section(cg, rbss_fd, rbss_rounds, traek, native))
    else:
        L.append("## Pinocchio's generated code (CppADCodeGen)\n")
        L.append("Not part of this run (`PEERS_CODEGEN=0`).\n")
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
    if cg:
        i = cg["info"]
        L.append(f"| generated code | {i.get('cppadcg_version', '?')} (PyPI `cmeel-cppadcodegen`), "
                 f"{i.get('cppad_version', '?')} (PyPI `cmeel-cppad`), Pinocchio "
                 f"{i.get('cg_pinocchio_version', '?')} `CodeGenConstraintDynamics`; the C compiled by "
                 f"{i.get('cg_gcc', '?')}: `{i.get('cg_flags_portable', '?')}` and "
                 f"`{i.get('cg_flags_native', '?')}` (`-march=native` = {i.get('cg_native_march', '?')}) |")
    L.append(f"| rbss | `{os.path.relpath(r.get('rbss_binary', 'target/release/rbss'), ROOT)}` built {r.get('rbss_mtime', '?')} "
             f"from a working tree at commit {git_head()} ({rustc}), no `target-cpu` |")
    if native:
        L.append(f"| rbss, native | `{os.path.relpath(native['binary'], ROOT)}` built {native['mtime']} "
                 f"(`RBSS_NATIVE`; to be built with `RUSTFLAGS=\"-C target-cpu=native\"`: "
                 f"rustc's `native` is {native['cpu']} here) |")
    L.append(f"| date | timing runs from {win['start'][0]} to {win['end'][0][11:]} |")
    L.append(f"| machine | nproc = {nproc}, CPU `{cpu_model()}`, load average (1, 5, 15 min) before the "
             f"timing runs {' '.join(win['start'][1])}, after them {' '.join(win['end'][1])} |")
    L.append(f"| masses [kg] | lower link, upper link, platform: {r['masses']} (paper-example.md: 30.630528372500, 31.365661053441, 74.160674941682) |")
    L.append("")
    # keep the derivatives' section (deriv_report.py, run_derivatives.sh) of the previous file
    path = os.path.join(outdir, "RESULT.md")
    keep = ""
    if os.path.exists(path):
        old = open(path).read()
        a, b = old.find("<!-- derivatives:"), old.find("<!-- /derivatives -->")
        if a >= 0 and b > a:
            keep = "\n" + old[a:b + len("<!-- /derivatives -->")] + "\n"
    with open(path, "w") as f:
        f.write("\n".join(L) + "\n" + keep)
    print("\n".join(L[4:4 + len(calls) + 3]))


def bench_rows(path):
    """forward_dynamics and inverse_dynamics (None when absent), the median over the rounds
    PATH/r*/solvers.csv of `rbss bench solvers`, and forward_dynamics' rounds."""
    fds, ids = [], []
    rounds = sorted(d for d in os.listdir(path) if re.fullmatch(r"r\d+", d)) if os.path.isdir(path) else []
    if not rounds:
        die(f"no rounds of `rbss bench solvers` in {path}")
    for d in rounds:
        rows = read_csv_str(os.path.join(path, d, "solvers.csv"))
        fd = [float(row["ns_per_call"]) for row in rows if row["solver"] == "forward_dynamics"]
        if not fd:
            die(f"no forward_dynamics row in {path}/{d}/solvers.csv")
        fds.append(fd[0])
        ids += [float(row["ns_per_call"]) for row in rows if row["solver"] == "inverse_dynamics"]
    med = lambda v: sorted(v)[len(v) // 2]
    return med(fds), (med(ids) if len(ids) == len(rounds) else None), fds


def rustc_native_cpu():
    """The CPU rustc's `target-cpu=native` selects on this machine (`rustc --print target-cpus`)."""
    if not shutil.which("rustc"):
        return "?"
    r = subprocess.run(["rustc", "--print", "target-cpus"], capture_output=True, text=True)
    m = re.search(r"^\s*native\b.*\(currently (\S+?)\)", r.stdout, re.M)
    return m.group(1) if m else "?"


# issue 19's targets: rbss forward_dynamics this many times faster than the peer, same build class
TARGETS = (("Pinocchio's generated `constraintDynamics`", 4.0), ("numeric Pinocchio `constraintDynamics`", 15.0))


def targets_section(t, cg, rbss_fd, native):
    out = ["Issue 19's targets, as speed-ups of rbss `forward_dynamics` over the peer (peer time / "
           "rbss time), each against the rbss of the same build class (numeric Pinocchio is "
           "built without `-march` only; its row against the native rbss is for information):\n"]
    out.append("| peer | build | peer | rbss | speed-up | target | met |")
    out.append("|---|---|---:|---:|---:|---:|---|")
    rows = []
    if cg:
        ct = cg["time"]
        rows.append((TARGETS[0], "portable", ct["cg_constraintDynamics_portable"], rbss_fd))
        if native:
            rows.append((TARGETS[0], "native", ct["cg_constraintDynamics_native"], native["fd"]))
    rows.append((TARGETS[1], "portable", t["pin_constraintDynamics"], rbss_fd))
    if native:
        rows.append(((TARGETS[1][0], None), "portable peer, native rbss (info)",
                     t["pin_constraintDynamics"], native["fd"]))
    for (name, target), b, peer, ours in rows:
        sp = peer / ours
        met = "—" if target is None else ("yes" if sp >= target else "no")
        tg = "" if target is None else f">= {target:g}×"
        out.append(f"| {name} | {b} | {fmt_ns(peer)} | {fmt_ns(ours)} | {sp:.2f}× | {tg} | {met} |")
    out.append("")
    return out


def codegen_section(cg, rbss_fd, rbss_rounds, traek, native):
    t, i = cg["time"], cg["info"]
    tape = i.get("cg_tape", "").split()
    tape = dict(zip(tape[::2], tape[1::2]))
    tk = {s["k"] for s in traek}
    allk = {s["k"] for s in cg["state"]}
    out = []
    out.append("## Pinocchio's generated code (CppADCodeGen)\n")
    out.append(
        "Pinocchio's `CodeGenConstraintDynamics` (`pinocchio/codegen/cppadcg-algo.hpp`) records "
        "`pinocchio::constraintDynamics` on `CppAD::AD<CppAD::cg::CG<double>>` for the same model as "
        "the numeric peer (the tree of six `RX -> RY -> PZ` legs and the free-flyer platform, six "
        "`CONTACT_3D` loop closures, default `ProximalSettings`: mu = 0, one iteration), and "
        "CppADCodeGen writes it out as one straight-line C function "
        f"(`build/codegen/src/constraintDynamics_forward_zero.c`: {cg['c_assign']} assignments, "
        f"{cg['c_aux']} auxiliary doubles; a tape of {tape.get('variables', '?')} variables, "
        f"{tape.get('inputs', '?')} inputs `[q, v, tau]`, {tape.get('outputs', '?')} outputs "
        "`[ddq, lambda_c]`). `codegen_gen.cpp` generates it; `codegen_harness.cpp` links the C "
        "compiled twice and calls the generated function directly (inputs packed once, outside "
        "the timing) at the timing state of the table above, in this run's order: harness, "
        "generated-code harness, `rbss bench solvers`. Timing: 3 rounds per build, alternating, "
        "each the median over 201 batches of 2000 calls; the median round is reported.\n")
    ref = {"portable": rbss_fd, "native": native["fd"] if native else rbss_fd}
    out.append("| call | median per call | the 3 rounds | ratio to rbss forward_dynamics, same build |")
    out.append("|---|---:|---|---:|")
    out.append(f"| rbss `forward_dynamics` (`rbss bench solvers`, this run), portable | {fmt_ns(rbss_fd)} | "
               f"{', '.join(fmt_ns(x) for x in rbss_rounds)} | 1.00× |")
    if native:
        out.append(f"| rbss `forward_dynamics` (`rbss bench solvers`, this run), `target-cpu=native` | "
                   f"{fmt_ns(native['fd'])} | {', '.join(fmt_ns(x) for x in native['rounds'])} | 1.00× |")
    for b in ("portable", "native"):
        flags = i.get(f"cg_flags_{b}", "?")
        rounds = ", ".join(fmt_ns(float(x)) for x in cg.get(f"cg_rounds_{b}", []))
        ns = t[f"cg_constraintDynamics_{b}"]
        out.append(f"| Pinocchio generated `constraintDynamics`, the C with `gcc {flags}` | {fmt_ns(ns)} | "
                   f"{rounds} | {ns / ref[b]:.2f}× |")
    num = t.get("cg_pin_constraintDynamics_numeric")
    if num:
        out.append(f"| (info) Pinocchio numeric `constraintDynamics`, in the same process | {fmt_ns(num)} | | "
                   f"{num / rbss_fd:.2f}× |")
    if not native:
        out.append("")
        out.append("(No native rbss in this run: the native build's ratio is over the portable rbss.)")
    out.append("")
    out.append("Agreement of the generated function's outputs, max over the states of "
               "max |a - b| / max |b| (rbss: the "
               f"{len(tk)} TraekP states of the next section, rbss's `U` in, its `Xddot` and `lambda` "
               "compared, mapped as there; numeric Pinocchio: `constraintDynamics` at the same "
               "`q, v, tau`, at those states and the timing state):\n")
    out.append("| check | C, portable | C, -march=native |")
    out.append("|---|---:|---:|")

    def mx(key, build, states):
        return max(s[key] for s in cg["state"] if s["build"] == build and s["k"] in states)
    for label, key, states in (
            ("accelerations vs rbss (mapped Ẍ)", "acc_vs_rbss", tk),
            ("multipliers vs rbss (λ = -R λ_c)", "lambda_vs_rbss", tk),
            ("accelerations vs numeric Pinocchio `constraintDynamics` (ddq)", "acc_vs_pin", allk),
            ("multipliers vs numeric Pinocchio (λ_c)", "lambda_vs_pin", allk)):
        out.append(f"| {label} | {mx(key, 'portable', states):.1e} | {mx(key, 'native', states):.1e} |")
    pin_vs_rbss = max(s["pin_acc_vs_rbss"] for s in cg["state"] if s["build"] == "portable" and s["k"] in tk)
    out.append("")
    out.append(f"(Numeric Pinocchio's accelerations vs rbss on the same states: {pin_vs_rbss:.1e}.) "
               "The -march=native build contracts multiply-adds into FMAs (GCC's default "
               "`-ffp-contract=fast` for GNU C), so its rounding differs from the portable build's.\n")
    out.append(
        "Notes. The generated code replaces the numeric call's tree traversals, joint-type dispatch "
        "and dynamic-size Eigen loops by the flattened arithmetic of this one model (the LDLᵀ "
        "factorisation of the contact KKT system included): the counterpart closest to rbss's own "
        "generated kernels. It is compiled with `-O3`, not with Pinocchio's default `-Ofast` "
        "(`CodeGenBase::compileLib`), to keep IEEE arithmetic like the other peers and rbss. The "
        "harness itself is built without `-march` (an earlier attempt found a `-march=native` build "
        "against the prebuilt `libpinocchio_default.so` aborting with `boost::bad_get`), so only the "
        "generated C gets the native flags. A one-off comparison of the same C on the Intel Xeon (cooperlake) "
        "of an earlier run (2026-11-25, a standalone driver): `-O3 -mavx` (VEX encoding, no FMA, outputs bit-identical to the portable build) "
        "took 3.5 µs against 4.6 µs for plain `-O3` (SSE2), and `-O3 -march=native "
        "-ffp-contract=off` 3.45 µs: most of the native gain is the AVX encoding of this large scalar "
        "function (three-operand instructions, fewer register copies), the rest FMA. About 3 % of "
        "the time is the twelve `sincos` calls on the legs' angles (glibc's libm). An earlier, "
        "unrecorded attempt had measured 3.13 µs (portable) and 2.42 µs (native); the figures above "
        "are this run's, on the machine of the table below.\n")
    return out


ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def git_head():
    r = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    if r.returncode != 0:
        return "unknown"
    # the script's own outputs do not make the tree "changed"
    d = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no", "--", ".",
                        ":!bench/peers/RESULT.md", ":!bench/peers/peers.csv",
                        ":!bench/peers/derivatives.csv"], capture_output=True, text=True)
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
    if len(sys.argv) not in (4, 5, 6) or sys.argv[1] not in ("states", "report"):
        die("usage: peers.py states BUILD RBSS | peers.py report BUILD OUTDIR [RBSS [RBSS_NATIVE]]")
    if sys.argv[1] == "states":
        states(sys.argv[2], sys.argv[3])
    else:
        report(sys.argv[2], sys.argv[3])
