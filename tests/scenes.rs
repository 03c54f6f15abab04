//! Scenes end to end: every single-task scene of the five-bar generates and compiles (one
//! temporary crate with all of them as modules, one `cargo build`), and each one's solvers give
//! the numbers of the full `five_bar` crate; frozen parameters are folded in and the others
//! still read at run time; a solver of a task the scene lacks does not compile, and the error
//! names the task (also for the linearisation, the `derivatives` task's). The two scene
//! examples of scenes/README.md are compiled and run in the same crate.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use rbss_codegen::scene::{Task, parse_scene_in};
use rbss_runtime::{
    Baumgarte, Coordinates, Data, ForwardDynamicsDerivatives, IntegrateOptions, Linearization,
    Method, Model, Simulator, Stabilization, StepDerivatives, forward_dynamics_derivatives,
    inverse_dynamics, inverse_dynamics_full, inverse_kinematics, linearize, rk4_step_derivatives,
};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The generated module of a scene (its text as a scene file), named `name`.
fn module(name: &str, scene_text: &str) -> String {
    let shown = format!("{name}.toml");
    let scene =
        parse_scene_in(&shown, scene_text, root().join("scenes")).unwrap_or_else(|d| panic!("{d}"));
    let g = rbss_codegen::generate_scene(&scene, "rbss-runtime", &mut |_| {})
        .unwrap_or_else(|e| panic!("{e}"));
    let file = format!("src/{name}.rs");
    g.files
        .into_iter()
        .find(|(p, _)| p.to_string_lossy() == file)
        .map(|(_, c)| c)
        .unwrap_or_else(|| panic!("no {file} in the generated crate"))
}

/// A crate depending on the runtime (the workspace's lock file, offline) with the given
/// modules and `main.rs`; returns `cargo build`'s output.
fn build_crate(dir: &Path, modules: &[(String, String)], main: &str) -> std::process::Output {
    let src = dir.join("src");
    std::fs::create_dir_all(&src).unwrap();
    let cargo_toml = format!(
        "[package]\nname = \"scene_check\"\nversion = \"0.0.0\"\nedition = \"2024\"\npublish = false\n\n\
         [dependencies]\nrbss-runtime = {{ path = {:?} }}\nlibm = \"0.2\"\n\n[workspace]\n",
        root().join("runtime").display().to_string()
    );
    std::fs::write(dir.join("Cargo.toml"), cargo_toml).unwrap();
    std::fs::copy(root().join("Cargo.lock"), dir.join("Cargo.lock")).unwrap();
    let mut main_rs = String::new();
    for (name, text) in modules {
        std::fs::write(src.join(format!("{name}.rs")), text).unwrap();
        writeln!(
            main_rs,
            "#[allow(clippy::approx_constant, dead_code)]\n#[rustfmt::skip]\nmod {name};"
        )
        .unwrap();
    }
    main_rs.push_str(main);
    std::fs::write(src.join("main.rs"), main_rs).unwrap();
    Command::new(env!("CARGO"))
        .args(["build", "--offline", "--quiet", "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .env("CARGO_TARGET_DIR", work_dir().join("target"))
        .env_remove("RUSTFLAGS")
        .output()
        .expect("cannot run cargo")
}

fn work_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("scenes")
}

/// The rust block after `<!-- scene example: NAME -->` in scenes/README.md, and the toml block.
fn readme_example(name: &str) -> (String, String) {
    let readme = std::fs::read_to_string(root().join("scenes/README.md")).unwrap();
    let marker = format!("<!-- scene example: {name} -->");
    let at = readme
        .find(&marker)
        .unwrap_or_else(|| panic!("scenes/README.md has no `{marker}`"));
    let rest = &readme[at..];
    let block = |fence: &str| {
        let start = rest
            .find(fence)
            .unwrap_or_else(|| panic!("no {fence} block after {marker}"))
            + fence.len();
        let len = rest[start..].find("```").unwrap();
        rest[start..start + len]
            .trim_start_matches('\n')
            .to_string()
    };
    (block("```toml"), block("```rust"))
}

fn parse_line(out: &str, key: &str) -> Vec<f64> {
    let line = out
        .lines()
        .find(|l| l.split_whitespace().next() == Some(key))
        .unwrap_or_else(|| panic!("no line `{key}` in the output:\n{out}"));
    // `key 1.0 2.0` or `key [1.0, 2.0]` (a `{:?}` array).
    line.split_whitespace()
        .skip(1)
        .map(|v| v.trim_matches(|c| c == '[' || c == ']' || c == ','))
        .filter(|v| !v.is_empty())
        .map(|v| {
            v.parse()
                .unwrap_or_else(|e| panic!("`{v}` in `{line}`: {e}"))
        })
        .collect()
}

fn assert_close(what: &str, got: &[f64], want: &[f64], tol: f64) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (i, (a, b)) in got.iter().zip(want).enumerate() {
        assert!(
            (a - b).abs() <= tol * b.abs().max(1.0),
            "{what}[{i}]: scene {a:e}, full crate {b:e}"
        );
    }
}

// The five-bar's states of the checks, shared by the scene crate (as text) and the full crate.
const XDOT: [f64; 6] = [0.3, -0.2, 0.1, 0.25, -0.05, 0.04];
const XDDOT: [f64; 6] = [1.0, -2.0, 0.5, 0.7, 0.2, -0.3];

const MAIN: &str = r#"
use rbss_runtime::*;

fn show(key: &str, v: &[f64]) {
    let s: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
    println!("{key} {}", s.join(" "));
}

const XDOT: [f64; 6] = [0.3, -0.2, 0.1, 0.25, -0.05, 0.04];
const XDDOT: [f64; 6] = [1.0, -2.0, 0.5, 0.7, 0.2, -0.3];

fn main() {
    let m = Model::new(five_bar_ik::FiveBar::default());
    let mut d = Data::new(&m);
    inverse_kinematics(&m, &mut d, &[0.02, 0.31]).unwrap();
    show("ik", &d.x);

    let m = Model::new(five_bar_fk::FiveBar::default());
    let mut d = Data::new(&m);
    let q = [m.structure().home[0] + 0.01, m.structure().home[2] - 0.02];
    forward_kinematics(&m, &mut d, &q).unwrap();
    show("fk", &d.x);

    let m = Model::new(five_bar_velocity::FiveBar::default());
    let mut d = Data::new(&m);
    inverse_velocity(&m, &mut d, &[0.1, -0.2]).unwrap();
    show("velocity", &d.xdot);

    let m = Model::new(five_bar_acceleration::FiveBar::default());
    let mut d = Data::new(&m);
    inverse_velocity(&m, &mut d, &[0.1, -0.2]).unwrap();
    inverse_acceleration(&m, &mut d, &[0.5, 0.3]).unwrap();
    show("acceleration", &d.xddot);

    let m = Model::new(five_bar_inverse_dynamics::FiveBar::default());
    let mut d = Data::new(&m);
    d.xdot = XDOT;
    d.xddot = XDDOT;
    inverse_dynamics(&m, &mut d, None).unwrap();
    show("inverse_dynamics", d.u());

    let m = Model::new(five_bar_forward_dynamics::FiveBar::default());
    let mut d = Data::new(&m);
    d.xdot = XDOT;
    forward_dynamics(&m, &mut d, &[0.1, -0.2], None, Baumgarte::NONE).unwrap();
    show("forward_dynamics", &d.xddot);

    let m = Model::new(five_bar_simulate::FiveBar::default());
    let mut d = Data::new(&m);
    let x0 = d.x;
    let options = IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::Projection);
    let mut sim = Simulator::new(&m, &mut d, 0.0, &x0, &[0.0; 6], options).unwrap();
    let mut control = |_t: f64, _x: &[f64; 6], _v: &[f64; 6], u: &mut [f64]| {
        u[0] = 0.05;
        u[1] = -0.05;
        Ok(())
    };
    sim.run(&m, &mut d, 0.2, &mut control, |_| {}).unwrap();
    show("simulate", sim.x());

    let m = Model::new(five_bar_energy::FiveBar::default());
    let mut e = [0.0; 2];
    tasks::Energy::energy(m.kernels(), &m.structure().home.try_into().unwrap(), &XDOT, &mut e);
    show("energy", &e);

    // Frozen: every parameter folded in, or only l1 (then l2 is still read at run time).
    let m = Model::new(five_bar_ik_frozen::FiveBar::default());
    let mut d = Data::new(&m);
    inverse_kinematics(&m, &mut d, &[0.02, 0.31]).unwrap();
    show("ik_frozen", &d.x);
    let p = five_bar_ik_l1::Params { l2: 0.26, ..Default::default() };
    let m = Model::new(five_bar_ik_l1::FiveBar::new(&p));
    let mut d = Data::new(&m);
    inverse_kinematics(&m, &mut d, &[0.02, 0.31]).unwrap();
    show("ik_l1", &d.x);

    // The loop kinds' scenes: a hinge and a point_on_line (inverse kinematics to inverse
    // dynamics), springs and a loop closing in a turning plane (simulation).
    let m = Model::new(spatial_crank_id::SpatialCrank::default());
    let mut d = Data::new(&m);
    inverse_kinematics(&m, &mut d, &[m.structure().home[1] - 0.3]).unwrap();
    inverse_velocity(&m, &mut d, &[0.4]).unwrap();
    inverse_acceleration(&m, &mut d, &[-0.7]).unwrap();
    inverse_dynamics(&m, &mut d, None).unwrap();
    show("crank_x", &d.x);
    show("crank_u", d.u());
    let m = Model::new(leg_four_bar_sim::LegFourBar::default());
    let mut d = Data::new(&m);
    let x0 = d.x;
    let options = IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::Projection);
    let mut sim = Simulator::new(&m, &mut d, 0.0, &x0, &[0.0; 5], options).unwrap();
    let mut control = |_t: f64, _x: &[f64; 5], _v: &[f64; 5], u: &mut [f64]| {
        u[0] = 0.0;
        u[1] = 0.05;
        Ok(())
    };
    sim.run(&m, &mut d, 0.2, &mut control, |_| {}).unwrap();
    show("leg_sim", sim.x());

    // The derivatives task: forward dynamics' derivatives, the linearisation on the manifold
    // (at the home, held still) and an RK4 step's Jacobians, from its kernels alone.
    let m = Model::new(five_bar_derivatives::FiveBar::default());
    let mut d = Data::new(&m);
    d.xdot = XDOT;
    let mut fdd = ForwardDynamicsDerivatives::new();
    forward_dynamics_derivatives(&m, &mut d, &mut fdd, &[0.1, -0.2], None).unwrap();
    show("fdd_dx", fdd.dxddot_dx.as_slice());
    let mut d = Data::new(&m);
    d.xdot = [0.0; 6];
    let mut lin = Linearization::new();
    linearize(&m, &mut d, &mut lin, &[0.1, -0.2], None, Coordinates::Outputs).unwrap();
    let (mut a, mut b) = ([0.0; 16], [0.0; 8]);
    lin.state_space(&mut a, &mut b).unwrap();
    show("lin_a", &a);
    show("lin_b", &b);
    let mut d = Data::new(&m);
    d.xdot = XDOT;
    let mut st = StepDerivatives::new();
    rk4_step_derivatives(&m, &mut d, &mut st, &[0.1, -0.2], 1e-3, Baumgarte::NONE).unwrap();
    show("rk4_jacobian", &st.jacobian[..12 * 14]);

    readme_ik().unwrap();
    readme_id().unwrap();
}
"#;

fn full_five_bar() -> (Model<five_bar::FiveBar, 6, 4>, Data<6, 4>) {
    let m = Model::new(five_bar::FiveBar::default());
    let d = Data::new(&m);
    (m, d)
}

#[test]
fn scenes_compile_and_match_the_full_crate() {
    // Every single-task scene of the five-bar, and two frozen ones.
    let mut modules: Vec<(String, String)> = Task::ALL
        .iter()
        .map(|t| {
            let name = format!("five_bar_{}", t.name());
            let text = format!(
                "model = \"../models/five_bar.toml\"\ntasks = [\"{}\"]\n",
                t.name()
            );
            let m = module(&name, &text);
            (name, m)
        })
        .collect();
    modules.push((
        "five_bar_ik_frozen".into(),
        module(
            "five_bar_ik_frozen",
            "model = \"../models/five_bar.toml\"\ntasks = [\"ik\"]\nfreeze = \"all\"\n",
        ),
    ));
    modules.push((
        "five_bar_ik_l1".into(),
        module(
            "five_bar_ik_l1",
            "model = \"../models/five_bar.toml\"\ntasks = [\"ik\"]\nfreeze = [\"l1\"]\n",
        ),
    ));

    // Exactly the kernels of the task, and its traits, nothing else.
    let kernels_of = |text: &str| -> Vec<String> {
        text.lines()
            .filter_map(|l| l.strip_prefix("pub fn "))
            .map(|l| l.split('(').next().unwrap().to_string())
            .collect()
    };
    for (name, text) in &modules[..Task::ALL.len()] {
        let task = Task::ALL
            .iter()
            .find(|t| name == &format!("five_bar_{}", t.name()))
            .unwrap();
        let mut want: Vec<&str> = vec![];
        let mut all = vec![*task];
        all.extend_from_slice(task.implies());
        for t in &all {
            for k in t.kernels() {
                if !want.contains(k) {
                    want.push(k);
                }
            }
        }
        // `closure_check` exists only for models whose loops leave components out (the
        // five-bar's left-out `z` is constant: nothing to check).
        want.retain(|&k| k != "closure_check");
        let mut got = kernels_of(text);
        got.sort();
        want.sort();
        assert_eq!(got, want, "{name}: kernels");
        assert!(
            text.lines().nth(2).unwrap().starts_with("// scene: "),
            "{name}: the header records the scene"
        );
        assert!(!text.contains("impl Kernels"), "{name}");
    }
    // Frozen: no parameter read, or only the ones not frozen.
    let frozen = &modules[Task::ALL.len()].1;
    assert!(
        frozen.contains("pub const K: usize = 0;"),
        "every parameter frozen"
    );
    let l1 = &modules[Task::ALL.len() + 1].1;
    assert!(
        l1.contains("- `c[0]` = ") && !l1.contains("= l1\n") && l1.contains("l2"),
        "only l1 frozen"
    );

    // scenes/README.md's examples, as functions of the same crate.
    let mut main = MAIN.to_string();
    for (name, func) in [
        ("stewart_6ups_ik", "readme_ik"),
        ("stewart_6ups_id", "readme_id"),
    ] {
        let (toml, rust) = readme_example(name);
        let file = std::fs::read_to_string(root().join(format!("scenes/{name}.toml"))).unwrap();
        assert_eq!(toml, file, "README's scene `{name}` is scenes/{name}.toml");
        modules.push((name.to_string(), module(name, &file)));
        write!(
            main,
            "\nfn {func}() -> Result<(), Box<dyn std::error::Error>> {{\n{rust}\nOk(())\n}}\n"
        )
        .unwrap();
    }

    for name in ["spatial_crank_id", "leg_four_bar_sim"] {
        let file = std::fs::read_to_string(root().join(format!("scenes/{name}.toml"))).unwrap();
        modules.push((name.to_string(), module(name, &file)));
    }

    let dir = work_dir().join("ok");
    let out = build_crate(&dir, &modules, &main);
    assert!(
        out.status.success(),
        "the scene crate does not compile:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(work_dir().join("target/debug/scene_check"))
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let out = String::from_utf8(run.stdout).unwrap();

    // The same with the full crate.
    let (m, mut d) = full_five_bar();
    inverse_kinematics(&m, &mut d, &[0.02, 0.31]).unwrap();
    let ik = d.x;
    assert_close("ik", &parse_line(&out, "ik"), &ik, 1e-14);
    assert_close("ik_frozen", &parse_line(&out, "ik_frozen"), &ik, 1e-12);
    let (m, mut d) = full_five_bar();
    let q = [m.structure().home[0] + 0.01, m.structure().home[2] - 0.02];
    rbss_runtime::forward_kinematics(&m, &mut d, &q).unwrap();
    assert_close("fk", &parse_line(&out, "fk"), &d.x, 1e-14);
    let (m, mut d) = full_five_bar();
    rbss_runtime::inverse_velocity(&m, &mut d, &[0.1, -0.2]).unwrap();
    assert_close("velocity", &parse_line(&out, "velocity"), &d.xdot, 1e-14);
    rbss_runtime::inverse_acceleration(&m, &mut d, &[0.5, 0.3]).unwrap();
    assert_close(
        "acceleration",
        &parse_line(&out, "acceleration"),
        &d.xddot,
        1e-14,
    );
    let (m, mut d) = full_five_bar();
    d.xdot = XDOT;
    d.xddot = XDDOT;
    inverse_dynamics(&m, &mut d, None).unwrap();
    assert_close(
        "inverse_dynamics",
        &parse_line(&out, "inverse_dynamics"),
        d.u(),
        1e-14,
    );
    let (m, mut d) = full_five_bar();
    d.xdot = XDOT;
    rbss_runtime::forward_dynamics(&m, &mut d, &[0.1, -0.2], None, Baumgarte::NONE).unwrap();
    assert_close(
        "forward_dynamics",
        &parse_line(&out, "forward_dynamics"),
        &d.xddot,
        1e-14,
    );
    let (m, mut d) = full_five_bar();
    let x0 = d.x;
    let options = IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::Projection);
    let mut sim = Simulator::new(&m, &mut d, 0.0, &x0, &[0.0; 6], options).unwrap();
    let mut control = |_t: f64, _x: &[f64; 6], _v: &[f64; 6], u: &mut [f64]| {
        u[0] = 0.05;
        u[1] = -0.05;
        Ok(())
    };
    sim.run(&m, &mut d, 0.2, &mut control, |_| {}).unwrap();
    assert_close("simulate", &parse_line(&out, "simulate"), sim.x(), 1e-12);
    let mut e = [0.0; 2];
    rbss_runtime::Dynamics::energy(
        m.kernels(),
        &m.structure().home.try_into().unwrap(),
        &XDOT,
        &mut e,
    );
    assert_close("energy", &parse_line(&out, "energy"), &e, 1e-14);
    // The derivatives scene: the same derivatives, linearisation and step Jacobians.
    let (m, mut d) = full_five_bar();
    d.xdot = XDOT;
    let mut fdd = ForwardDynamicsDerivatives::new();
    forward_dynamics_derivatives(&m, &mut d, &mut fdd, &[0.1, -0.2], None).unwrap();
    assert_close(
        "fdd_dx",
        &parse_line(&out, "fdd_dx"),
        fdd.dxddot_dx.as_slice(),
        1e-14,
    );
    let (m, mut d) = full_five_bar();
    d.xdot = [0.0; 6];
    let mut lin = Linearization::new();
    linearize(
        &m,
        &mut d,
        &mut lin,
        &[0.1, -0.2],
        None,
        Coordinates::Outputs,
    )
    .unwrap();
    let (mut a, mut b) = ([0.0; 16], [0.0; 8]);
    lin.state_space(&mut a, &mut b).unwrap();
    assert_close("lin_a", &parse_line(&out, "lin_a"), &a, 1e-14);
    assert_close("lin_b", &parse_line(&out, "lin_b"), &b, 1e-14);
    assert!(b.iter().any(|v| v.abs() > 1e-3), "B = {b:?}");
    let (m, mut d) = full_five_bar();
    d.xdot = XDOT;
    let mut st = StepDerivatives::new();
    rk4_step_derivatives(&m, &mut d, &mut st, &[0.1, -0.2], 1e-3, Baumgarte::NONE).unwrap();
    assert_close(
        "rk4_jacobian",
        &parse_line(&out, "rk4_jacobian"),
        &st.jacobian[..12 * 14],
        1e-14,
    );
    // Only l1 frozen: l2 = 0.26 from the run-time Params changes the solution like the full
    // crate's with the same Params.
    let p = five_bar::Params {
        l2: 0.26,
        ..Default::default()
    };
    let m = Model::new(five_bar::FiveBar::new(&p));
    let mut d = Data::new(&m);
    inverse_kinematics(&m, &mut d, &[0.02, 0.31]).unwrap();
    let ik_l1 = parse_line(&out, "ik_l1");
    assert_close("ik_l1", &ik_l1, &d.x, 1e-12);
    assert!((ik_l1[0] - ik[0]).abs() > 1e-3, "l2 is read at run time");

    // The loop kinds' scenes against their full crates.
    let m = Model::new(spatial_crank::SpatialCrank::default());
    let mut d = Data::new(&m);
    inverse_kinematics(&m, &mut d, &[m.structure().home[1] - 0.3]).unwrap();
    rbss_runtime::inverse_velocity(&m, &mut d, &[0.4]).unwrap();
    rbss_runtime::inverse_acceleration(&m, &mut d, &[-0.7]).unwrap();
    inverse_dynamics(&m, &mut d, None).unwrap();
    assert_close("crank_x", &parse_line(&out, "crank_x"), &d.x, 1e-14);
    assert_close("crank_u", &parse_line(&out, "crank_u"), d.u(), 1e-12);
    let m = Model::new(leg_four_bar::LegFourBar::default());
    let mut d = Data::new(&m);
    let x0 = d.x;
    let options = IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::Projection);
    let mut sim = Simulator::new(&m, &mut d, 0.0, &x0, &[0.0; 5], options).unwrap();
    let mut control = |_t: f64, _x: &[f64; 5], _v: &[f64; 5], u: &mut [f64]| {
        u[0] = 0.0;
        u[1] = 0.05;
        Ok(())
    };
    sim.run(&m, &mut d, 0.2, &mut control, |_| {}).unwrap();
    assert_close("leg_sim", &parse_line(&out, "leg_sim"), sim.x(), 1e-12);

    // scenes/README.md: the 1 kHz IK loop's last legs and the inverse dynamics' last forces.
    let m = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut d = Data::new(&m);
    for k in 0..1000 {
        let t = k as f64 * 1e-3;
        inverse_kinematics(&m, &mut d, &[0.1, 0.0, 0.94 + 0.01 * t, 0.1, 0.0, 0.0]).unwrap();
    }
    let legs: Vec<f64> = m.structure().actuated.iter().map(|&j| d.x[j]).collect();
    assert_close("README ik", &parse_line(&out, "legs"), &legs, 1e-12);
    let m = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut d = Data::new(&m);
    let w = 3.0 * std::f64::consts::PI;
    for k in 0..=200 {
        let t = k as f64 * 0.01;
        let (s, c) = (w * t).sin_cos();
        let pose = [0.1, 0.0, 0.94 + 0.01 * s, 0.1, 0.0, 0.0];
        let rate = [0.0, 0.0, 0.01 * w * c, 0.0, 0.0, 0.0];
        let accel = [0.0, 0.0, -0.01 * w * w * s, 0.0, 0.0, 0.0];
        inverse_dynamics_full(&m, &mut d, &pose, &rate, &accel, None).unwrap();
    }
    assert_close("README id", &parse_line(&out, "U"), d.u(), 1e-9);
}

#[test]
fn a_missing_task_is_a_compile_error_naming_it() {
    let ik = module(
        "five_bar_ik",
        "model = \"../models/five_bar.toml\"\ntasks = [\"ik\"]\n",
    );
    let main = r#"
fn main() {
    use rbss_runtime::*;
    let m = Model::new(five_bar_ik::FiveBar::default());
    let mut d = Data::new(&m);
    inverse_kinematics(&m, &mut d, &[0.02, 0.31]).unwrap();
    forward_dynamics(&m, &mut d, &[0.1, -0.2], None, Baumgarte::NONE).unwrap();
}
"#;
    let out = build_crate(
        &work_dir().join("missing"),
        &[("five_bar_ik".into(), ik)],
        main,
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "compiled:\n{stderr}");
    for want in [
        "the trait bound `FiveBar: rbss_runtime::tasks::ForwardDynamics<6, 4>` is not satisfied: `FiveBar` was generated without the `forward_dynamics` task",
        "add \"forward_dynamics\" to the `tasks` of its scene file and regenerate",
    ] {
        assert!(stderr.contains(want), "no `{want}` in:\n{stderr}");
    }
    // Only that call fails: inverse kinematics is offered.
    assert_eq!(stderr.matches("error[E0277]").count(), 1, "{stderr}");
}

/// The linearisation and the step's Jacobians are the `derivatives` task's: a scene with
/// forward dynamics alone does not compile them, and the error names the task.
#[test]
fn linearize_needs_the_derivatives_task() {
    let fd = module(
        "five_bar_forward_dynamics",
        "model = \"../models/five_bar.toml\"\ntasks = [\"forward_dynamics\"]\n",
    );
    let main = r#"
fn main() {
    use rbss_runtime::*;
    let m = Model::new(five_bar_forward_dynamics::FiveBar::default());
    let mut d = Data::new(&m);
    forward_dynamics(&m, &mut d, &[0.1, -0.2], None, Baumgarte::NONE).unwrap();
    let mut lin = Linearization::new();
    linearize(&m, &mut d, &mut lin, &[0.1, -0.2], None, Coordinates::Outputs).unwrap();
}
"#;
    let out = build_crate(
        &work_dir().join("missing_derivatives"),
        &[("five_bar_forward_dynamics".into(), fd)],
        main,
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "compiled:\n{stderr}");
    for want in [
        "the trait bound `FiveBar: rbss_runtime::tasks::Derivatives<6, 4>` is not satisfied: `FiveBar` was generated without the `derivatives` task",
        "add \"derivatives\" to the `tasks` of its scene file and regenerate",
    ] {
        assert!(stderr.contains(want), "no `{want}` in:\n{stderr}");
    }
    assert_eq!(stderr.matches("error[E0277]").count(), 1, "{stderr}");
}

#[test]
fn every_committed_scene_generates_what_its_tasks_need() {
    let mut n = 0;
    for entry in std::fs::read_dir(root().join("scenes")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let shown = format!("scenes/{}", path.file_name().unwrap().to_string_lossy());
        let text = std::fs::read_to_string(&path).unwrap();
        let scene =
            parse_scene_in(&shown, &text, root().join("scenes")).unwrap_or_else(|d| panic!("{d}"));
        let g = rbss_codegen::generate_scene(&scene, "rbss-runtime", &mut |_| {})
            .unwrap_or_else(|e| panic!("{e}"));
        let names: Vec<&str> = g.report.kernels.iter().map(|k| k.name).collect();
        // `closure_check` only where the model has loop components to check: as in its full
        // crate.
        let model = scene.model_path();
        let model = model.file_stem().unwrap().to_string_lossy();
        let full =
            std::fs::read_to_string(root().join(format!("generated/{model}/src/{model}.rs")))
                .unwrap();
        let mut want = scene.kernels();
        if !full.contains("pub fn closure_check(") {
            want.retain(|&k| k != "closure_check");
        }
        if !full.contains("pub fn forward_dynamics_solve(") {
            want.retain(|&k| k != "forward_dynamics_solve");
        }
        assert_eq!(names, want, "{shown}");
        assert!(!names.is_empty(), "{shown}");
        n += 1;
    }
    assert!(n >= 6, "{n} scenes in scenes/");
}

/// The build-script API: the same scene without a file, the same errors.
#[test]
fn build_script_scene() {
    use rbss_codegen::build::Scene;
    let out = work_dir().join("build_rs");
    std::fs::create_dir_all(&out).unwrap();
    // Run from the package root (where cargo runs the tests), as a build script is.
    let err = Scene::new("models/five_bar.toml")
        .tasks(&["ik", "simulaton"])
        .freeze(&["l3"])
        .compile(&out)
        .unwrap_err()
        .to_string();
    assert!(err.contains("error: unknown task `simulaton`"), "{err}");
    assert!(err.contains("did you mean `simulate`?"), "{err}");
    Scene::new("models/five_bar.toml")
        .tasks(&["ik", "velocity"])
        .freeze(&["l1"])
        .compile(&out)
        .unwrap_or_else(|e| panic!("{e}"));
    let text = std::fs::read_to_string(out.join("five_bar_ik_velocity.rs")).unwrap();
    assert!(
        text.contains("// scene: build.rs scene  sha256: ")
            && text.contains("tasks: ik, velocity  freeze: l1"),
        "{}",
        &text[..400]
    );
    assert!(!text.contains("//!"), "inner docs stripped for include!");
    let err = Scene::new("models/five_bar.toml")
        .tasks(&["fk"])
        .freeze(&["l3"])
        .compile(&out)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("unknown parameter `l3` in `freeze`") && err.contains("did you mean `l1`"),
        "{err}"
    );
}
