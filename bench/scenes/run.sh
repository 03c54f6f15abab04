#!/usr/bin/env bash
# Scenes against the full model (BENCHMARKS.md, "Scenes"): for the 6-UPS and the five-bar, the
# full generated crate and each scene of scenes/ (ik, id, sim), frozen as committed and with
# run-time parameters: generation time, generated lines, release compile time of the crate, size
# of a small program using it (bench/scenes/main.rs, stripped) and the median ns per call of
# its kernels and solver. Needs target/release/rbss-codegen
# (`cargo build --release -p rbss -p rbss-codegen --bins`). Writes $W/results.tsv.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
W=${W:-$ROOT/target/scene-bench}
CODEGEN=$ROOT/target/release/rbss-codegen
export CARGO_TARGET_DIR=$W/target
rm -rf "$W/ws"
mkdir -p "$W/ws/crates" "$W/ws/bins" "$W/scenes"
RES=$W/results.tsv
printf 'robot\tvariant\tjob\tgen_s\tlines\tcompile_wall_s\tcompile_cpu_s\tbinary_bytes\tname\tns\n' > "$RES"

# The robot's type, as the generated crate names it (`pub struct Stewart6Ups`).
robot_type() { grep -h '^pub struct ' "$1"/src/*.rs | grep -v '^pub struct Params' | head -1 | awk '{print $3}'; }

# The crates: name -> generation time and lines.
declare -A GEN LINES ROBOT
for robot in stewart_6ups five_bar; do
  v=${robot}_full
  s=$( { /usr/bin/time -f %e "$CODEGEN" "models/$robot.toml" --out "$W/ws/crates/$v" 2>&1 >/dev/null; } | tee "$W/gen_$v.txt" | tail -1)
  sed -i "s|name = \"$robot\"|name = \"$v\"|; s|path = \"../../runtime\"|path = \"$ROOT/runtime\"|" "$W/ws/crates/$v/Cargo.toml"
  GEN[$v]=$s; LINES[$v]=$(wc -l < "$W/ws/crates/$v/src/$robot.rs"); ROBOT[$v]=$robot
  for job in ik id sim; do
    for p in frozen rt; do
      v=${robot}_${job}_$p
      {
        echo "model = \"$ROOT/models/$robot.toml\""
        echo "name = \"$v\""
        grep '^tasks' "scenes/${robot}_$job.toml"
        [ $p = frozen ] && grep '^freeze' "scenes/${robot}_$job.toml"
        true
      } > "$W/scenes/$v.toml"
      s=$( { /usr/bin/time -f %e "$CODEGEN" --scene "$W/scenes/$v.toml" --out "$W/ws/crates/$v" 2>&1 >/dev/null; } | tee "$W/gen_$v.txt" | tail -1)
      sed -i '/^\[workspace\]$/d' "$W/ws/crates/$v/Cargo.toml"
      GEN[$v]=$s; LINES[$v]=$(wc -l < "$W/ws/crates/$v/src/$v.rs"); ROBOT[$v]=$robot
    done
  done
done

cat > "$W/ws/Cargo.toml" <<TOML
[workspace]
members = ["crates/*", "bins/*"]
resolver = "3"
TOML
cp Cargo.lock "$W/ws/Cargo.lock"

# The programs: every scene with its job, the full crate with every job.
for v in "${!GEN[@]}"; do
  robot=${ROBOT[$v]}
  if [[ $v == *_full ]]; then jobs="ik id sim"; else jobs=$(echo "$v" | sed -E "s/^${robot}_([a-z]+)_(frozen|rt)$/\1/"); fi
  for job in $jobs; do
    b=bin_${v}_$job
    mkdir -p "$W/ws/bins/$b/src"
    cat > "$W/ws/bins/$b/Cargo.toml" <<TOML
[package]
name = "$b"
version = "0.0.0"
edition = "2024"
publish = false

[dependencies]
rbss-runtime = { path = "$ROOT/runtime" }
robot = { package = "$v", path = "../../crates/$v" }
libc = "0.2"

[features]
ik = []
id = []
sim = []
default = ["$job"]
TOML
    cp bench/scenes/main.rs "$W/ws/bins/$b/src/main.rs"
    echo "type R = robot::$(robot_type "$W/ws/crates/$v");" > "$W/ws/bins/$b/robot.rs"
  done
done

cd "$W/ws"
cargo build --release --offline -q -p rbss-runtime
for v in $(printf '%s\n' "${!GEN[@]}" | sort); do
  touch "crates/$v/src/lib.rs"
  # Wall and CPU (user + sys, rustc included) seconds of compiling the robot crate alone.
  c=$( { /usr/bin/time -f '%e %U %S' cargo build --release --offline -q -p "$v" 2>&1; } | tail -1 | awk '{printf "%s\t%.2f", $1, $2 + $3}')
  for b in $(ls bins | grep "^bin_${v}_"); do
    job=${b##*_}
    cargo build --release --offline -q -p "$b"
    strip -o "$W/$b.stripped" "$CARGO_TARGET_DIR/release/$b"
    size=$(stat -c %s "$W/$b.stripped")
    "$CARGO_TARGET_DIR/release/$b" | while read -r name ns; do
      printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "${ROBOT[$v]}" "$v" "$job" "${GEN[$v]}" "${LINES[$v]}" "$c" "$size" "$name" "$ns" >> "$RES"
    done
  done
done
echo "wrote $RES"
