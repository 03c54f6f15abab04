#!/usr/bin/env bash
# Instructions per call of every solver of `rbss bench solvers` and of the kernels it calls,
# counted by callgrind: the table's ratio in instructions rather than nanoseconds. Instruction
# counts repeat exactly for the same binary and inputs, whatever else the machine is doing, so
# they show what a change to a solver did where the time ratio drowns in the shared machine's
# noise (±0.5 on single ratios). They do not see caches, branch prediction or the width of the
# core: confirm a gain with `rbss bench solvers` before quoting it.
#
#   bench/instructions.sh MODEL [CALLS]      (after cargo build --release --features rbss/full;
#                                             RBSS=path/to/rbss for another build)
#
# Runs `rbss bench solvers --model MODEL` under callgrind with RBSS_BENCH_CALLS=CALLS (default
# 400): every solver and kernel called CALLS times, no calibration. A function's instructions per
# call are its inclusive count over its calls (the few set-up calls of the table are included).
# The solvers' entry points are `#[inline(never)]` in the runtime, so that they are functions
# of their own here.
set -euo pipefail
cd "$(dirname "$0")/.."
model=${1:?usage: bench/instructions.sh MODEL [CALLS]}
calls=${2:-400}
bin=${RBSS:-target/release/rbss}
out=$(mktemp -d)
trap '[ -n "${KEEP:-}" ] || rm -rf "$out"' EXIT
RBSS_BENCH_CALLS=$calls valgrind --tool=callgrind --callgrind-out-file="$out/cg" \
  "$bin" bench solvers --model "$model" --out "$out" --batches 1 >/dev/null 2>"$out/valgrind.log" || {
  cat "$out/valgrind.log"; exit 1; }
callgrind_annotate --inclusive=yes --tree=caller "$out/cg" >"$out/tree.txt" 2>/dev/null
# Per function: inclusive instructions (the `*` line) over the calls its callers made.
awk '
  /^ *[0-9,]+ .*< / {
    if (match($0, /\([0-9,]+x\)/)) {
      c = substr($0, RSTART + 1, RLENGTH - 3); gsub(",", "", c); pending += c
    }
    next
  }
  /^ *[0-9,]+ .*\* / {
    ir = $1; gsub(",", "", ir)
    name = $0; sub(/^[^*]*\* +[^:]*:/, "", name); sub(/ \[.*$/, "", name)
    if (pending > 0) { print name "\t" ir "\t" pending }
    pending = 0; next
  }
  /^$/ { pending = 0 }
' "$out/tree.txt" >"$out/funcs.tsv"
awk -F'\t' -v model="$model" -v csv="$out/solvers.csv" '
  BEGIN {
    split("ik_warm=inverse_kinematics::inverse_kinematics fk_warm=forward_kinematics::forward_kinematics inverse_velocity=inverse_kinematics::inverse_velocity inverse_acceleration=inverse_kinematics::inverse_acceleration forward_velocity=forward_kinematics::forward_velocity forward_acceleration=forward_kinematics::forward_acceleration inverse_dynamics=inverse_dynamics::inverse_dynamics forward_dynamics=forward_dynamics::forward_dynamics id_sample=inverse_dynamics::inverse_dynamics_full", pairs, " ")
    for (i in pairs) { split(pairs[i], kv, "="); sym[kv[1]] = "rbss_runtime::algorithm::" kv[2] }
  }
  FNR == NR { per[$1] = $2 / $3; next }
  FNR == 1 { next }
  {
    # solvers.csv: solver,ns_per_call,kernels_ns,ratio,kernel_calls ("1 jacobian + 1 gamma")
    n = split($0, f, ","); solver = f[1]; list = f[5]
    kir = 0; k = split(list, terms, " \\+ ")
    for (t = 1; t <= k; t++) {
      split(terms[t], ck, " "); kname = "rbss::robots::" model "::" ck[2]
      if (!(kname in per)) { print "no count for " kname > "/dev/stderr"; kir = -1; break }
      kir += ck[1] * per[kname]
    }
    s = sym[solver]
    if (!(s in per) || kir <= 0) { printf "| %s | %s | ? | ? | ? |\n", model, solver; next }
    printf "| %s | %s | %.0f | %.0f | %.2f |\n", model, solver, per[s], kir, per[s] / kir
  }
' "$out/funcs.tsv" FS=',' "$out/solvers.csv" | {
  echo "| robot | solver | instructions per call | kernels' instructions | ratio |"
  echo "|---|---|---:|---:|---:|"
  cat
}
