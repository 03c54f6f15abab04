#!/usr/bin/env python3
"""Markdown tables of bench/scenes/run.sh's results (results.tsv, gen_*.txt) for BENCHMARKS.md."""
import csv, re, sys, pathlib

w = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "target/scene-bench")
rows = list(csv.DictReader(open(w / "results.tsv"), delimiter="\t"))
JOBS = {"ik": ("1 kHz IK", "inverse_kinematics"), "id": ("inverse dynamics along a path", "inverse_dynamics_full"), "sim": ("full simulation", "simulator_step")}


def ops(variant):
    """kernel -> (mul, add, div, fn) from rbss-codegen's report."""
    out = {}
    for line in open(w / f"gen_{variant}.txt"):
        m = re.match(r"rbss-codegen:\s+(\w+)\s.*?(\d+) mul, (\d+) add, (\d+) div, (\d+) fn", line)
        if m and not line.startswith("rbss-codegen: ["):
            out[m.group(1)] = tuple(int(g) for g in m.groups()[1:])
    return out


def get(variant, job, name):
    for r in rows:
        if r["variant"] == variant and r["job"] == job and r["name"] == name:
            return r
    return None


for robot in ["stewart_6ups", "five_bar"]:
    print(f"\n#### {robot}\n")
    print("| scene (job) | crate | kernels | gen. s | lines | compile s (wall / CPU) | binary bytes | solver ns/call |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for job, (title, solver) in JOBS.items():
        for variant in [f"{robot}_full", f"{robot}_{job}_frozen", f"{robot}_{job}_rt"]:
            r = get(variant, job, f"solver/{solver}")
            kind = {"full": "full model", "frozen": "scene, frozen", "rt": "scene, run-time params"}[variant.rsplit("_", 1)[1]]
            k = ", ".join(sorted(ops(variant)))
            if variant.endswith("_full"):
                k = f"all {len(ops(variant))}"
            print(f"| {title} (`{solver}`) | {kind} | {k} | {r['gen_s']} | {r['lines']} | {r['compile_wall_s']} / {r['compile_cpu_s']} | {r['binary_bytes']} | {float(r['ns']):.0f} |")
    print()
    print("| kernel | ops run-time params (mul, add, div, fn) | ops frozen | ns run-time | ns frozen |")
    print("|---|---|---|---:|---:|")
    seen = set()
    for job in JOBS:
        rt, fr = ops(f"{robot}_{job}_rt"), ops(f"{robot}_{job}_frozen")
        for r in rows:
            if r["variant"] == f"{robot}_{job}_rt" and r["name"].startswith("kernel/"):
                name = r["name"][7:]
                if name in seen:
                    continue
                seen.add(name)
                f = get(f"{robot}_{job}_frozen", job, r["name"])
                o1, o2 = rt[name], fr[name]
                print(f"| `{name}` | {', '.join(map(str, o1))} ({sum(o1)}) | {', '.join(map(str, o2))} ({sum(o2)}) | {float(r['ns']):.1f} | {float(f['ns']):.1f} |")
