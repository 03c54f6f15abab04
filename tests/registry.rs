//! The robot registry (build.rs): `rbss` knows every crate in `generated/` without a list in
//! its source, and every subcommand with `--model` accepts each of them.

mod common;

use std::path::{Path, PathBuf};

use common::rbss;
use rbss::robots::NAMES;
use rbss_runtime::Kernels;

/// Left out of the default build (build.rs, `OPTIONAL`); registered with `all-robots`.
const OPTIONAL: &[&str] = &[
    "stewart_2stage",
    "five_bar_turned",
    "four_bar_rod",
    "gear_pair",
    "leg_four_bar",
    "slider_crank",
    "spatial_crank",
    "cassie_legs",
];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The generated crates: `generated/NAME/src/NAME.rs`, sorted.
fn generated() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(root().join("generated"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| {
            root()
                .join("generated")
                .join(n)
                .join("src")
                .join(format!("{n}.rs"))
                .is_file()
        })
        .collect();
    names.sort();
    names
}

#[test]
fn the_registry_is_exactly_generated() {
    let all = generated();
    let want: Vec<&String> = all
        .iter()
        .filter(|n| cfg!(feature = "all-robots") || !OPTIONAL.contains(&n.as_str()))
        .collect();
    assert_eq!(
        NAMES.iter().collect::<Vec<_>>(),
        want,
        "rbss::robots::NAMES against generated/*/src/NAME.rs"
    );
    // The main job's robot is always there; the optional ones only with the feature.
    assert!(NAMES.contains(&"stewart_6ups"));
    for o in OPTIONAL {
        assert_eq!(
            NAMES.contains(o),
            cfg!(feature = "all-robots") && all.iter().any(|n| n == o),
            "{o}"
        );
    }
    // `rbss list`: one line per robot, in this order, with the structure of its kernels.
    let (ok, stdout, stderr) = rbss(&["list"]);
    assert!(ok, "{stderr}");
    let listed: Vec<&str> = stdout
        .lines()
        .map(|l| l.split_whitespace().next().unwrap())
        .collect();
    assert_eq!(listed, NAMES);
    for (line, name) in stdout.lines().zip(NAMES) {
        let (n, m) = rbss::with_robot!(*name, |model| {
            let s = model.structure();
            assert_eq!(s.name, *name, "the module's Structure names its robot");
            Ok::<_, String>((s.coordinates.len(), s.constraints.len()))
        })
        .unwrap();
        assert!(
            line.contains(&format!("n = {n:>2}, m = {m:>2}")),
            "{line} (n = {n}, m = {m})"
        );
    }
}

/// Every generated crate's manifest (`rbss-manifest.toml`, which build.rs reads) agrees with
/// its kernels: name, sizes, actuated count, the module it names, and its model file.
#[test]
fn manifests_describe_their_crates() {
    for name in generated() {
        let dir = root().join("generated").join(&name);
        let text = std::fs::read_to_string(dir.join("rbss-manifest.toml"))
            .unwrap_or_else(|e| panic!("{name}: no manifest: {e}"));
        let t: toml::Table = text.parse().unwrap_or_else(|e| panic!("{name}: {e}"));
        let s = |k: &str| t[k].as_str().unwrap_or_else(|| panic!("{name}: {k}"));
        let i = |k: &str| t[k].as_integer().unwrap_or_else(|| panic!("{name}: {k}")) as usize;
        assert_eq!(s("name"), name);
        assert_eq!(s("module"), format!("src/{name}.rs"));
        let module = std::fs::read_to_string(dir.join(s("module"))).unwrap();
        assert!(
            module.contains(&format!("pub struct {} ", s("type"))),
            "{name}: no `pub struct {}` in the module",
            s("type")
        );
        assert!(
            module.contains(&format!(
                "// model: {}  sha256: {}",
                s("model"),
                s("model_sha256")
            )),
            "{name}: the module's header names another model file or hash"
        );
        assert!(root().join(s("model")).is_file(), "{name}: {}", s("model"));
        assert!(s("generator").starts_with("rbss-codegen "));
        if NAMES.contains(&name.as_str()) {
            let (n, m, k) = rbss::with_robot!(name.as_str(), |model| {
                let st = model.structure();
                Ok::<_, String>((
                    st.coordinates.len(),
                    st.constraints.len(),
                    st.actuated.len(),
                ))
            })
            .unwrap();
            assert_eq!((i("n"), i("m"), i("actuated")), (n, m, k), "{name}");
        }
    }
}

fn join(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:e}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// Each registered robot through every subcommand that takes `--model`: at its home assembly
/// inverse kinematics gives back the home and forward kinematics its outputs; `eval` the
/// kernels there; inverse dynamics and the round trip along its trajectory file when it has
/// one, else an error about the trajectory (never "unknown robot").
#[test]
fn every_subcommand_accepts_every_registered_robot() {
    let tmpdir = tempfile::tempdir().unwrap();
    let tmp = tmpdir.path();
    for name in NAMES {
        let (home, outputs, actuated, f_home) =
            rbss::with_robot!(*name, |model| Ok::<_, String>(home_of(&model))).unwrap();
        // With passive degrees of freedom, the tasks that need one actuated coordinate per
        // degree of freedom say so (forward kinematics, inverse dynamics, the round trip).
        let full = rbss::with_robot!(*name, |model| Ok::<_, String>(
            model.structure().fully_actuated()
        ))
        .unwrap();
        let unavailable = |stderr: &str, task: &str| {
            assert!(
                stderr.contains(&format!("{task} is unavailable"))
                    && stderr.contains("the others are passive"),
                "{name}: {stderr}"
            );
        };
        let f_max = f_home.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(
            f_max < 1e-9,
            "{name}: home is assembled (max |f| = {f_max:e})"
        );

        let (ok, stdout, stderr) =
            rbss(&["ik", "--model", name, "--pose", &join(&outputs), "--json"]);
        assert!(ok, "{name}: ik: {stderr}");
        let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        for (j, h) in home.iter().enumerate() {
            let got = v["x"][j].as_f64().unwrap();
            assert!(
                (got - h).abs() < 1e-8,
                "{name}: ik X[{j}] = {got}, home {h}"
            );
        }

        let (ok, stdout, stderr) =
            rbss(&["fk", "--model", name, "--q", &join(&actuated), "--json"]);
        if full {
            assert!(ok, "{name}: fk: {stderr}");
            let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
            for (i, o) in outputs.iter().enumerate() {
                let got = v["outputs"][i].as_f64().unwrap();
                assert!(
                    (got - o).abs() < 1e-8,
                    "{name}: fk output {i} = {got}, home {o}"
                );
            }
        } else {
            assert!(!ok, "{name}: fk with passive degrees of freedom: {stdout}");
            unavailable(&stderr, "forward kinematics");
        }

        // Forward dynamics at home (no "U": zero forces), then a short simulation from there.
        let state = tmp.join(format!("{name}-state.json"));
        let zero = vec![0.0; home.len()];
        std::fs::write(
            &state,
            serde_json::json!({"X": home, "Xdot": zero}).to_string(),
        )
        .unwrap();
        let (ok, stdout, stderr) =
            rbss(&["fd", "--model", name, "--state", state.to_str().unwrap()]);
        assert!(ok, "{name}: fd: {stderr}");
        let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(
            v["Xddot"].as_array().unwrap().len(),
            home.len(),
            "{name}: fd"
        );
        assert_eq!(
            v["lambda"].as_array().unwrap().len(),
            f_home.len(),
            "{name}: fd"
        );
        let res = v["residual"][0]
            .as_f64()
            .unwrap()
            .max(v["residual"][1].as_f64().unwrap());
        assert!(res < 1e-8, "{name}: fd residual {res:e}");
        let sim = tmp.join(format!("{name}-simulate"));
        let (ok, stdout, stderr) = rbss(&[
            "simulate",
            "--model",
            name,
            "--state",
            state.to_str().unwrap(),
            "--t-end",
            "0.01",
            "--out",
            sim.to_str().unwrap(),
        ]);
        assert!(ok, "{name}: simulate: {stderr}");
        assert!(stdout.contains("simulate.csv"), "{name}: {stdout}");
        assert!(sim.join("simulate.csv").is_file() && sim.join("simulate.png").is_file());

        let states = tmp.join(format!("{name}.json"));
        let xdot = vec![0.0; home.len()];
        std::fs::write(
            &states,
            serde_json::json!({"states": [{"X": home, "Xdot": xdot}]}).to_string(),
        )
        .unwrap();
        let (ok, stdout, stderr) = rbss(&[
            "eval",
            "--model",
            name,
            "--states",
            states.to_str().unwrap(),
        ]);
        assert!(ok, "{name}: eval: {stderr}");
        let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        for (i, want) in f_home.iter().enumerate() {
            assert_eq!(
                v["states"][0]["f"][i].as_f64().unwrap(),
                *want,
                "{name}: f[{i}]"
            );
        }

        let traj = Path::new("models/trajectories").join(format!("{name}.toml"));
        let has_traj = root().join(&traj).is_file();
        let csv = tmp.join(format!("{name}.csv"));
        let (ok, _, stderr) = rbss(&[
            "inverse-dynamics",
            "--model",
            name,
            "--trajectory",
            traj.to_str().unwrap(),
            "--samples",
            "3",
            "--csv",
            csv.to_str().unwrap(),
        ]);
        assert!(!stderr.contains("unknown robot"), "{name}: {stderr}");
        assert_eq!(ok, has_traj && full, "{name}: inverse-dynamics: {stderr}");
        if has_traj && !full {
            unavailable(&stderr, "inverse dynamics");
        }
        if has_traj && full {
            let rows = std::fs::read_to_string(&csv).unwrap().lines().count();
            assert_eq!(rows, 4, "{name}: header and 3 samples");
        }
        // The round trip over a short time (its own tests check the bound).
        let out = tmp.join(format!("{name}-roundtrip"));
        let (ok, stdout, stderr) = rbss(&[
            "roundtrip",
            "--model",
            name,
            "--t-end",
            "0.05",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(!stderr.contains("unknown robot"), "{name}: {stderr}");
        assert_eq!(ok, has_traj && full, "{name}: roundtrip: {stderr}");
        if has_traj && !full {
            unavailable(&stderr, "inverse dynamics");
        }
        if has_traj && full {
            assert!(stdout.contains("round-trip max output error: "), "{stdout}");
        }
        // The solver table, one batch per measurement (a study: feature `studies`).
        if !cfg!(feature = "studies") {
            continue;
        }
        let (ok, stdout, stderr) = rbss(&[
            "bench",
            "solvers",
            "--model",
            name,
            "--batches",
            "1",
            "--out",
            tmp.join(name).to_str().unwrap(),
        ]);
        if full {
            assert!(ok, "{name}: bench solvers: {stderr}");
        } else {
            // Passive degrees of freedom: the rows of the tasks the robot has, and a line that
            // names the ones it has not (tests/bench_solvers.rs checks the rows).
            assert!(ok, "{name}: bench solvers: {stderr}");
            assert!(
                stdout.contains(&format!("{name}: ")) && stdout.contains("inverse_dynamics"),
                "{name}: bench solvers with passive degrees of freedom: {stdout}"
            );
        }
    }
    let (ok, _, stderr) = rbss(&["fk", "--model", "no_such_robot", "--q", "0"]);
    assert!(!ok);
    assert!(
        stderr.contains(&format!(
            "unknown robot `no_such_robot`; known: {}",
            NAMES.join(", ")
        )),
        "{stderr}"
    );
}

/// The home assembly `X`, its outputs, its actuated coordinates and `f` there.
fn home_of<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &rbss_runtime::Model<K, N, M>,
) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let s = model.structure();
    let x: [f64; N] = s.home.try_into().unwrap();
    let mut f = [0.0; M];
    model.kernels().constraints(&x, &mut f);
    (
        x.to_vec(),
        s.outputs.iter().map(|&j| x[j]).collect(),
        s.actuated.iter().map(|&j| x[j]).collect(),
        f.to_vec(),
    )
}
