"""The report of bench/peers/run_derivatives.sh (standard library only; run with the venv's python).

  deriv_report.py BUILD OUTDIR RBSS_DERIV [RBSS_DERIV_NATIVE]
      -> OUTDIR/derivatives.csv (every round's timings and ratios) and the section between
         DERIV_BEGIN and DERIV_END in OUTDIR/RESULT.md (replaced; appended when absent;
         peers.py report keeps it when it rewrites the file)

Reads BUILD/deriv/: rounds.txt (the load average before and after each round), rbss_{portable,
native}_rN.txt (runtime/examples/peers_derivatives.rs), peers_rN.txt (deriv_harness.cpp),
cg_status.txt (why the generated-derivatives peer is missing, when it is), and
BUILD/codegen/dgen_info.txt.
"""

import csv
import datetime
import glob
import os
import re
import subprocess
import sys

from peers import cpu_model, fmt_ns, git_head

DERIV_BEGIN = "<!-- derivatives: written by deriv_report.py (run_derivatives.sh) -->"
DERIV_END = "<!-- /derivatives -->"


def die(msg):
    sys.exit(f"bench/peers: ERROR: {msg}")


def kv_times(path):
    t = {}
    with open(path) as f:
        for line in f:
            p = line.split()
            if len(p) == 3 and p[0] == "time":
                t[p[1]] = float(p[2])
    return t


def parse_peers(path):
    res = {"pin": [], "cg": [], "mj": [], "fd_by_hand_vs_mjd": [], "time": {}, "kv": {}}
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] in ("pin", "cg", "mj", "fd_by_hand_vs_mjd"):
                d = {"k": int(p[1])}
                for i in range(2, len(p) - 1, 2):
                    try:
                        d[p[i]] = float(p[i + 1])
                    except ValueError:
                        d[p[i]] = p[i + 1]
                res[p[0]].append(d)
            elif p[0] == "time":
                res["time"][p[1]] = float(p[2])
            else:
                res["kv"][p[0]] = " ".join(p[1:])
    return res


def rounds_load(path):
    loads = {}
    with open(path) as f:
        for line in f:
            p = line.split()
            if len(p) >= 7 and p[0] == "round":
                loads.setdefault(int(p[1]), {})[p[2]] = {"when": f"{p[3]} {p[4]}", "load": p[5:8]}
    return loads


def main():
    if len(sys.argv) < 4:
        die("usage: deriv_report.py BUILD OUTDIR RBSS_DERIV [RBSS_DERIV_NATIVE]")
    build, outdir, rbin = sys.argv[1], sys.argv[2], sys.argv[3]
    nbin = sys.argv[4] if len(sys.argv) > 4 else None
    d = os.path.join(build, "deriv")
    loads = rounds_load(os.path.join(d, "rounds.txt"))
    rounds = sorted(loads)
    if not rounds:
        die(f"no rounds in {d}/rounds.txt")
    R = {}
    for r in rounds:
        R[r] = {"rbss": kv_times(os.path.join(d, f"rbss_portable_r{r}.txt")),
                "peers": parse_peers(os.path.join(d, f"peers_r{r}.txt"))}
        if nbin:
            R[r]["native"] = kv_times(os.path.join(d, f"rbss_native_r{r}.txt"))
    cg_status = None
    sp = os.path.join(d, "cg_status.txt")
    if os.path.exists(sp):
        with open(sp) as f:
            cg_status = f.read().strip()
    info = {}
    ip = os.path.join(build, "codegen", "dgen_info.txt")
    if cg_status is None and os.path.exists(ip):
        with open(ip) as f:
            for line in f:
                k, _, v = line.strip().partition(" ")
                info[k] = v

    # (label, peer key, build, rbss key): each peer over rbss's measure of the same build class
    comps = [
        ("Pinocchio `constraintDynamics` + `computeConstraintDynamicsDerivatives` (numeric)",
         "pin_constraintDynamics_plus_derivatives", "portable", "forward_dynamics_derivatives"),
        ("Pinocchio `computeConstraintDynamicsDerivatives` alone (after `constraintDynamics`)",
         "pin_computeConstraintDynamicsDerivatives", "portable", "forward_dynamics_derivatives"),
        ("Pinocchio generated (`CodeGenConstraintDynamicsDerivatives`), gcc -O3",
         "cg_constraintDynamicsDerivatives_portable", "portable", "forward_dynamics_derivatives"),
        ("Pinocchio generated, gcc -O3 -march=native",
         "cg_constraintDynamicsDerivatives_native", "native", "forward_dynamics_derivatives"),
        ("MuJoCo, RK4: `mj_step` differenced by hand, centred (`mjd_transitionFD` refuses RK4)",
         "mj_fd_by_hand_rk4_centred", "portable", "rk4_step_derivatives"),
        ("MuJoCo, RK4: `mj_step` differenced by hand, forward", "mj_fd_by_hand_rk4_forward", "portable",
         "rk4_step_derivatives"),
        ("MuJoCo `mjd_transitionFD`, Euler, centred", "mjd_transitionFD_euler_centred", "portable",
         "semi_implicit_euler_step_derivatives"),
        ("MuJoCo `mjd_transitionFD`, Euler, forward", "mjd_transitionFD_euler_forward", "portable",
         "semi_implicit_euler_step_derivatives"),
    ]
    rbss_rows = [("forward_dynamics", "`forward_dynamics` (reference)"),
                 ("forward_dynamics_derivatives", "`forward_dynamics_derivatives` (Ẍ, λ w.r.t. X, Ẋ, U)"),
                 ("linearize_outputs", "`linearize` (outputs) + `state_space`: A 12 × 12, B 12 × 6"),
                 ("rk4_step_derivatives", "`rk4_step_derivatives` (F_x 48 × 48, F_u 48 × 6), dt = 1 ms"),
                 ("semi_implicit_euler_step_derivatives", "`semi_implicit_euler_step_derivatives`, dt = 1 ms")]

    def rbss_ns(r, build, key):
        src = R[r]["native"] if (build == "native" and nbin) else R[r]["rbss"]
        return src.get(key)

    rows = []
    for r in rounds:
        l1 = loads[r]["start"]["load"][0]
        for key, _ in rbss_rows:
            rows.append([r, l1, "rbss", key, "portable", R[r]["rbss"].get(key, ""), "", "", "", ""])
            if nbin:
                rows.append([r, l1, "rbss", key, "native", R[r]["native"].get(key, ""), "", "", "", ""])
        for _, key, build, rkey in comps:
            ns = R[r]["peers"]["time"].get(key)
            if ns is None:
                continue
            ref = rbss_ns(r, build, rkey)
            rb = build if (build == "portable" or nbin) else "portable"
            rows.append([r, l1, "peer", key, build, ns, rkey, rb, ref, f"{ns / ref:.3f}"])
    with open(os.path.join(outdir, "derivatives.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["round", "load1_at_start", "kind", "measure", "build", "ns_per_call", "rbss_measure",
                    "rbss_build", "rbss_ns", "ratio_peer_over_rbss"])
        w.writerows(rows)

    # the quietest round: lowest 1-minute load at its start
    q = min(rounds, key=lambda r: float(loads[r]["start"]["load"][0]))
    P, T = R[q]["peers"], R[q]["peers"]["time"]

    def ratio_range(key, build, rkey):
        v = []
        for r in rounds:
            ns = R[r]["peers"]["time"].get(key)
            ref = rbss_ns(r, build, rkey)
            if ns and ref:
                v.append(ns / ref)
        return (min(v), max(v)) if v else None

    L = [DERIV_BEGIN, "", "## Derivatives (issue 36): `run_derivatives.sh`", ""]
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    L.append(f"Written {now} by `bench/peers/run_derivatives.sh` at commit {git_head()}, "
             f"{len(rounds)} rounds; machine: {cpu_model()}, {os.cpu_count()} logical CPUs. "
             f"Round {q}, the quietest (1-minute load {' / '.join(loads[q]['start']['load'])} at its "
             f"start, {loads[q]['start']['when']} UTC), is quoted; the ratio columns give the range "
             f"over all rounds (each ratio within one round). Load per round: "
             + "; ".join(f"{r}: {loads[r]['start']['load'][0]} → {loads[r]['end']['load'][0]}" for r in rounds)
             + ".\n")
    L.append("Each peer over rbss's call that gives the same derivatives: Pinocchio's (constraint "
             "dynamics and its derivatives: q̈ and λ w.r.t. q, v, τ) over rbss's "
             "`forward_dynamics_derivatives` (Ẍ and λ w.r.t. X, Ẋ, U, forward dynamics included); "
             "MuJoCo's `mjd_transitionFD` (A 48 × 48, B 48 × 6 of one `mj_step`, by finite differences, "
             "eps 1e-6; for RK4, which it refuses, the same differences of `mj_step` by hand) over rbss's "
             "step Jacobians with the same integrator and step (RK4 with RK4, MuJoCo's semi-implicit "
             "Euler with rbss's). The generated C's native row over the native "
             "rbss" + (" (RBSS_DERIV_NATIVE)." if nbin else ": no native rbss in this run, so over the "
                       "portable one.") + "\n")
    if float(loads[q]["start"]["load"][0]) > 2 * (os.cpu_count() or 1):
        L.append(f"**Caution: a loaded machine** (load {loads[q]['start']['load'][0]} on {os.cpu_count()} "
                 f"CPUs). Every timing is wall-clock per call, the median over batches: rbss's batches "
                 f"last ~1 ms, the C++ harness's 10 to 100 ms (a fixed number of calls), so under load "
                 f"the peers' batches are preempted far more often than rbss's and their times inflate "
                 f"more (compare Pinocchio's `constraintDynamics` here with its quiet-machine time in the "
                 f"forward-dynamics table above): the ratios below overstate rbss's lead by an unknown "
                 f"factor. Re-run on a quiet machine before quoting them; the agreement numbers do not "
                 f"depend on the load.\n")
    L.append("| rbss | portable | " + ("native |" if nbin else "") )
    L.append("|---|---:|" + ("---:|" if nbin else ""))
    for key, label in rbss_rows:
        line = f"| {label} | {fmt_ns(R[q]['rbss'][key])} |"
        if nbin:
            line += f" {fmt_ns(R[q]['native'][key])} |"
        L.append(line)
    L.append("")
    L.append("| peer | time | over rbss (this round) | over rbss (all rounds) |")
    L.append("|---|---:|---:|---:|")
    for label, key, build, rkey in comps:
        if key not in T:
            continue
        rr = ratio_range(key, build, rkey)
        L.append(f"| {label} | {fmt_ns(T[key])} | {T[key] / rbss_ns(q, build, rkey):.2f}x | "
                 f"{rr[0]:.2f}x to {rr[1]:.2f}x |")
    if "mj_step_rk4" in T:
        L.append(f"\nFor scale: one MuJoCo `mj_step` {fmt_ns(T['mj_step_rk4'])} (RK4), "
                 f"{fmt_ns(T['mj_step_euler'])} (Euler); Pinocchio's `constraintDynamics` alone "
                 f"{fmt_ns(T['pin_constraintDynamics'])}.")
    if cg_status:
        L.append(f"\nPinocchio's generated derivatives are not in this run: {cg_status}")
    elif info:
        L.append(f"\nThe generated derivatives: {info.get('cg_c_lines', '?')} lines of C "
                 f"(`{info.get('cg_tape', '')}`), gcc `{info.get('cg_flags_portable', '')}` and "
                 f"`{info.get('cg_flags_native', '')}` (-march={info.get('cg_native_march', '?')}).")

    # targets (issue 36)
    fdd = R[q]["rbss"]["forward_dynamics_derivatives"]
    lin = R[q]["rbss"]["linearize_outputs"]
    rk4 = R[q]["rbss"]["rk4_step_derivatives"]
    L.append("\nIssue 36's targets (portable rbss, this round):\n")
    L.append("| target | measured | met |")
    L.append("|---|---:|---|")

    def met(ok):
        return "yes" if ok else "no"
    L.append(f"| forward-dynamics derivatives <= 4 µs | {fmt_ns(fdd)} | {met(fdd <= 4000)} |")
    pn = T.get("pin_constraintDynamics_plus_derivatives")
    if pn:
        L.append(f"| >= 5x faster than Pinocchio's numeric derivatives | {pn / fdd:.2f}x | {met(pn / fdd >= 5)} |")
    cgp = T.get("cg_constraintDynamicsDerivatives_portable")
    if cgp:
        L.append(f"| >= 3x faster than its generated version (gcc -O3) | {cgp / fdd:.2f}x | {met(cgp / fdd >= 3)} |")
    else:
        L.append("| >= 3x faster than its generated version | not measured (above) | - |")
    L.append(f"| manifold linearisation A, B <= 3 µs | {fmt_ns(lin)} | {met(lin <= 3000)} |")
    L.append(f"| RK4 step F_x, F_u <= 20 µs | {fmt_ns(rk4)} | {met(rk4 <= 20000)} |")
    mc = T.get("mj_fd_by_hand_rk4_centred")
    if mc:
        L.append(f"| >= 25x faster than MuJoCo's finite differences (RK4, centred, by hand) | {mc / rk4:.1f}x | {met(mc / rk4 >= 25)} |")
    mf = T.get("mj_fd_by_hand_rk4_forward")
    if mf:
        L.append(f"| the same, forward differences | {mf / rk4:.1f}x | {met(mf / rk4 >= 25)} |")
    eu = R[q]["rbss"]["semi_implicit_euler_step_derivatives"]
    me = T.get("mjd_transitionFD_euler_centred")
    if me:
        L.append(f"| (Euler: `mjd_transitionFD` centred over rbss's Euler step Jacobians) | {me / eu:.1f}x | {met(me / eu >= 25)} |")

    # agreement (round 1: the numbers do not depend on the round)
    A = R[rounds[0]]["peers"]
    L.append("\nAgreement with rbss at the same states (the 21 TraekP states and the timing state), "
             "max over the states of max |peer - rbss| / max |rbss| per matrix, in the peers' "
             "coordinates with rbss's perturbations as the columns (see `deriv_harness.cpp` for the "
             "map: Pinocchio's a and λ_c along rbss's X_j, Ẋ_j, U_j; the map's own derivatives in X by "
             "central differences with a Richardson step, ~1e-11):\n")

    def mx(lst, key, **f):
        v = [s[key] for s in lst if all(s.get(a) == b for a, b in f.items())]
        return f"{max(v):.1e}" if v else "-"
    L.append("| derivative | Pinocchio numeric | Pinocchio generated (portable) | generated (native) |")
    L.append("|---|---:|---:|---:|")
    for key, label in [("dacc_dX", "∂q̈/∂X"), ("dacc_dXd", "∂q̈/∂Ẋ"), ("dacc_dU", "∂q̈/∂U"),
                       ("dlambda_dX", "∂λ/∂X"), ("dlambda_dXd", "∂λ/∂Ẋ"), ("dlambda_dU", "∂λ/∂U")]:
        L.append(f"| {label} | {mx(A['pin'], key)} | {mx(A['cg'], key, build='portable')} | "
                 f"{mx(A['cg'], key, build='native')} |")
    L.append(f"| (values: q̈, λ) | {mx(A['pin'], 'acc_rel')}, {mx(A['pin'], 'lambda_rel')} | "
             f"generated vs numeric, all six: {mx(A['cg'], 'vs_pin', build='portable')} | "
             f"{mx(A['cg'], 'vs_pin', build='native')} |")
    L.append("\nMuJoCo's `mjd_transitionFD` against rbss's step Jacobians (A P(s) D vs P(s') F_x D along "
             "the 12 directions D of the constraint manifold, B vs P(s') F_u; P the map to MuJoCo's "
             "tangent state). MuJoCo's loop closures are soft (solref 0.002, solimp 0.9999: its "
             "accelerations differ from the hard constraints' by ~1e-4, RESULT.md above) and pull the "
             "state back to the manifold, so its full A differs from rbss's unstabilised F_x off the "
             "manifold (last columns, for information):\n")
    L.append("| integrator | differences | F_x on the manifold | F_u | F_x, all 48 directions | next state: pos [rad, m] / vel rel |")
    L.append("|---|---|---:|---:|---:|---:|")
    for integ in ("euler", "rk4"):
        for c in (1, 0):
            iname = "RK4 (by hand)" if integ == "rk4" else "Euler (`mjd_transitionFD`)"
            L.append(f"| {iname} | {'centred' if c else 'forward'} | "
                     f"{mx(A['mj'], 'F_manifold', integrator=integ, centred=c)} | "
                     f"{mx(A['mj'], 'F_u', integrator=integ, centred=c)} | "
                     f"{mx(A['mj'], 'F_full', integrator=integ, centred=c)} | "
                     f"{mx(A['mj'], 'next_pos', integrator=integ, centred=c)} / "
                     f"{mx(A['mj'], 'next_vel_rel', integrator=integ, centred=c)} |")
    hv = A["fd_by_hand_vs_mjd"]
    if hv:
        L.append(f"\nRK4 rows: MuJoCo 4.0.0's `mjd_transitionFD` stops with \"RK4 integrator is not "
                 f"supported\", so `deriv_harness.cpp` (`transition_fd`) makes the same differences by hand "
                 f"(one `mj_step` per perturbed state or control, the warm start restored each time); on "
                 f"Euler it agrees with `mjd_transitionFD` to {max(max(h['A'], h['B']) for h in hv):.1e} "
                 f"(max over the states, both schemes).")
    L.append(f"\nVersions: Pinocchio {A['kv'].get('pinocchio_version', '?')}, MuJoCo "
             f"{A['kv'].get('mujoco_version', '?')}; rbss: `{os.path.relpath(rbin, outdir)}`"
             + (f", native `{os.path.relpath(nbin, outdir)}`" if nbin else "") + ".")
    L.append("")
    L.append(DERIV_END)
    section = "\n".join(L) + "\n"

    path = os.path.join(outdir, "RESULT.md")
    text = open(path).read() if os.path.exists(path) else ""
    if DERIV_BEGIN in text and DERIV_END in text:
        a = text.index(DERIV_BEGIN)
        b = text.index(DERIV_END) + len(DERIV_END) + 1
        text = text[:a] + section + text[b:]
    else:
        text = text.rstrip("\n") + "\n\n" + section
    with open(path, "w") as f:
        f.write(text)
    print(section)


if __name__ == "__main__":
    main()
