//! The named-intermediate derivation (`rbss_codegen::derive`, what the kernels are generated
//! from) against the fully expanded one done independently with symbolica
//! (`rbss_codegen::expanded`): `f`, `G`, `gamma`, `M` and `psi` of the five-bar, the paper's
//! 6-UPS, the UR5, a 4-link chain, the spring pendulum (the joints' forces), every loop kind and
//! polynomial couplings at random states. The two share only the parsed model: one builds frames recursively
//! and takes the dynamics body by body (Newton-Euler projected on the Jacobians), the other
//! expands the frames and differentiates `T` as Lagrange's equations are written.
//!
//! The only test in this binary: it runs symbolica (one thread per user), behind the lock.

// Matrices over index pairs read best with explicit indices.
#![allow(clippy::needless_range_loop)]

use rbss_codegen::derive::Form;
use rbss_codegen::expanded;
use rbss_codegen::graph::Graph;
use symbolica::atom::{Atom, AtomCore, Symbol};
use symbolica::evaluate::{Instruction, Slot};

/// Evaluates symbolica atoms at `inputs` (values of `params`) through the evaluator's
/// instruction list.
fn eval_atoms(exprs: &[Atom], params: &[Atom], inputs: &[f64]) -> Vec<f64> {
    let ev = Atom::evaluator_multiple(exprs, params)
        .horner_iterations(1)
        .build()
        .expect("every symbol is an input");
    let ex = ev.export_instructions();
    let consts: Vec<f64> = ex.constants.iter().map(|c| c.re.to_f64()).collect();
    let mut slots: std::collections::HashMap<Slot, f64> = std::collections::HashMap::new();
    let read = |s: &Slot, slots: &std::collections::HashMap<Slot, f64>| -> f64 {
        match s {
            Slot::Param(i) => inputs[*i],
            Slot::Const(i) => consts[*i],
            other => slots[other],
        }
    };
    for ins in &ex.instructions {
        let (dst, val) = match ins {
            Instruction::Add(o, args, _) => (*o, args.iter().map(|a| read(a, &slots)).sum()),
            Instruction::Mul(o, args, _) => (*o, args.iter().map(|a| read(a, &slots)).product()),
            Instruction::Pow(o, b, e, _) => (*o, read(b, &slots).powi(*e as i32)),
            Instruction::Powf(o, b, e, _) => (*o, read(b, &slots).powf(read(e, &slots))),
            Instruction::Fun(o, call, _) => {
                let (sym, _, args) = &**call;
                let a = read(&args[0], &slots);
                let v = if *sym == Symbol::SIN {
                    a.sin()
                } else if *sym == Symbol::COS {
                    a.cos()
                } else if *sym == Symbol::SQRT {
                    a.sqrt()
                } else {
                    panic!("unexpected function {sym}")
                };
                (*o, v)
            }
            Instruction::Assign(o, s) => (*o, read(s, &slots)),
            other => panic!("unexpected instruction {other:?}"),
        };
        slots.insert(dst, val);
    }
    (0..exprs.len()).map(|j| slots[&Slot::Out(j)]).collect()
}

struct Rng(u64);
impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
}

fn compare(path: &str, source: &str, form: Form) {
    let model = rbss_codegen::parse::parse_model(path, source).unwrap_or_else(|e| panic!("{e:?}"));
    let n = model.coordinates.len();
    let np = model.parameters.len();
    let frozen = vec![false; np];
    let d = rbss_codegen::derive::derive_with(&model, true, &frozen, form, &mut |_| {})
        .unwrap_or_else(|e| panic!("{e:?}"));
    let _lock = rbss_codegen::lock::SymbolicaLock::acquire(|_| {}).unwrap();
    let e = expanded::derive(&model, true);
    let (e_mass, e_psi) = e.dynamics.as_ref().unwrap();
    let dy = d.dynamics.as_ref().unwrap();

    // Pairs (graph node, expanded atom) of every quantity.
    let mut ids = Vec::new();
    let mut atoms = Vec::new();
    let mut what = Vec::new();
    for i in 0..d.m {
        ids.push(d.f[i]);
        atoms.push(e.f[i].clone());
        what.push(format!("f[{i}]"));
        ids.push(d.gamma[i]);
        atoms.push(e.gamma[i].clone());
        what.push(format!("gamma[{i}]"));
        for j in 0..n {
            ids.push(d.g[i][j]);
            atoms.push(e.g[i][j].clone());
            what.push(format!("G[{i}][{j}]"));
        }
    }
    for i in 0..n {
        ids.push(dy.psi[i]);
        atoms.push(e_psi[i].clone());
        what.push(format!("psi[{i}]"));
        for j in i..n {
            ids.push(dy.mass[i][j]);
            atoms.push(e_mass[i][j].clone());
            what.push(format!("M[{i}][{j}]"));
        }
    }
    // Structural zeros agree exactly.
    for (k, (&id, a)) in ids.iter().zip(&atoms).enumerate() {
        if id == Graph::ZERO {
            assert!(
                a.is_zero(),
                "{path}: {} is a structural zero only in the graph",
                what[k]
            );
        }
    }
    let mut params: Vec<Atom> = (0..n).map(|i| Atom::var(expanded::q(i))).collect();
    params.extend((0..n).map(|i| Atom::var(expanded::v(i))));
    params.extend((0..np).map(|j| Atom::var(expanded::p(j))));
    params.push(Atom::var(expanded::pi_sym()));
    let pvals: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let home: Vec<f64> = model.coordinates.iter().map(|c| c.home).collect();
    let mut rng = Rng(7);
    let mut worst = 0.0f64;
    for _ in 0..5 {
        let x: Vec<f64> = home.iter().map(|h| h + rng.uniform(-0.2, 0.2)).collect();
        let v: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let mut inputs = x.clone();
        inputs.extend(&v);
        inputs.extend(&pvals);
        inputs.push(std::f64::consts::PI);
        let want = eval_atoms(&atoms, &params, &inputs);
        for (k, &id) in ids.iter().enumerate() {
            let got = d.graph.eval(id, &x, &v, &pvals);
            let err = (got - want[k]).abs() / (1.0 + want[k].abs());
            worst = worst.max(err);
            assert!(
                err < 1e-12,
                "{path}: {} = {got} (graph) vs {} (expanded)",
                what[k],
                want[k]
            );
        }
    }
    println!(
        "{path}: {} quantities, worst relative difference {worst:.1e}",
        ids.len()
    );
}

/// A 4-link spatial chain (alternating y and x joints), each tip's height read by an output:
/// deep enough that the two forms of the dynamics differ in every term.
const CHAIN: &str = r#"
coordinates = [
  { name = "th1", unit = "rad", home = 0.3 }, { name = "th2", unit = "rad", home = -0.4 },
  { name = "th3", unit = "rad", home = 0.5 }, { name = "th4", unit = "rad", home = 0.2 },
  { name = "z1", unit = "m", home = 0.2 }, { name = "z2", unit = "m", home = 0.4 },
  { name = "z3", unit = "m", home = 0.6 }, { name = "z4", unit = "m", home = 0.8 },
]
[robot]
name = "chain_4"
gravity = [0.5, -1, -9.81]
actuated = ["th1", "th2", "th3", "th4"]
outputs = ["z1", "z2", "z3", "z4"]
[parameters]
l = { value = 0.3, unit = "m" }
[[body]]
name = "link1"
transforms = ["Ry(th1)"]
mass = 1.5
com = [0.01, 0.02, 0.15]
inertia = [0.02, 0.025, 0.012, 0.001, -0.002, 0.003]
[[body]]
name = "link2"
parent = "link1"
transforms = ["Tz(l)", "Rx(th2)", "Rz(0.3)"]
mass = 1.2
com = [0.0, -0.01, 0.12]
inertia = [0.015, 0.02, 0.008, 0.0, 0.001, 0.0]
[[body]]
name = "link3"
parent = "link2"
transforms = ["Tz(l)", "Ry(th3)"]
mass = 0.9
com = [0.02, 0.0, 0.1]
inertia = [0.01, 0.012, 0.006, 0.0005, 0.0, -0.001]
[[body]]
name = "link4"
parent = "link3"
transforms = ["Tz(l)", "Rx(th4)", "Tx(0.05)"]
mass = 0.5
com = [0.0, 0.0, 0.08]
inertia = [0.004, 0.005, 0.002, 0.0, 0.0, 0.0]
[[loop]]
name = "tip1"
a = { body = "link1", transforms = ["Tz(l)"] }
b = { body = "world", transforms = ["Tz(z1)"] }
components = ["z"]
[[loop]]
name = "tip2"
a = { body = "link2", transforms = ["Tz(l)"] }
b = { body = "world", transforms = ["Tz(z2)"] }
components = ["z"]
[[loop]]
name = "tip3"
a = { body = "link3", transforms = ["Tz(l)"] }
b = { body = "world", transforms = ["Tz(z3)"] }
components = ["z"]
[[loop]]
name = "tip4"
a = { body = "link4", transforms = ["Tz(l)"] }
b = { body = "world", transforms = ["Tz(z4)"] }
components = ["z"]
"#;

/// Every loop kind beside the point and the weld: a hinge (axis y, its point components in the
/// frame of `b`), a distance, a point in a plane (along the axes of `a`) and a coupling, on
/// three spatial arms.
const KINDS: &str = r#"
coordinates = [
  { name = "a1", unit = "rad", home = 0.3 }, { name = "a2", unit = "rad", home = -0.4 },
  { name = "a3", unit = "rad", home = 0.5 }, { name = "b1", unit = "rad", home = 0.2 },
  { name = "b2", unit = "rad", home = 0.7 }, { name = "b3", unit = "rad", home = -0.3 },
  { name = "c1", unit = "rad", home = 0.9 }, { name = "c2", unit = "rad", home = 0.4 },
  { name = "s", unit = "m", home = 0.1 }, { name = "g", unit = "rad", home = 0.6 },
]
[robot]
name = "kinds"
gravity = [0.5, -1, -9.81]
actuated = ["a1", "c1"]
outputs = ["b1", "g"]
[parameters]
l = { value = 0.3, unit = "m" }
rod = { value = 0.35, unit = "m" }
ratio = { value = 2.5, unit = "1" }
[[body]]
name = "arm_a"
transforms = ["Rz(a1)", "Ry(a2)", "Tx(l)", "Ry(a3)"]
mass = 1.5
com = [0.1, 0.02, 0.01]
inertia = [0.02, 0.025, 0.012, 0.001, -0.002, 0.003]
[[body]]
name = "arm_b"
transforms = ["Ty(0.4)", "Rz(b1)", "Ry(b2)", "Tx(l)", "Ry(b3)"]
mass = 1.2
com = [0.1, -0.01, 0.02]
inertia = [0.015, 0.02, 0.008, 0.0, 0.001, 0.0]
[[body]]
name = "arm_c"
transforms = ["Tx(0.5)", "Rz(c1)", "Tx(l)", "Rx(c2)"]
mass = 0.9
com = [0.02, 0.0, 0.1]
inertia = [0.01, 0.012, 0.006, 0.0005, 0.0, -0.001]
[[body]]
name = "slider"
transforms = ["Rz(0.3)", "Tx(s)"]
mass = 0.5
com = [0, 0, 0]
inertia = [0.004, 0.005, 0.002, 0.0, 0.0, 0.0]
[[body]]
name = "wheel"
transforms = ["Tz(-0.2)", "Rz(g)"]
mass = 0.4
com = [0.05, 0, 0]
inertia = [0.004, 0.005, 0.002, 0.0, 0.0, 0.0]
[[loop]]
name = "hinge"
kind = "hinge"
axis = "y"
frame = "b"
a = { body = "arm_a", transforms = ["Tx(l)"] }
b = { body = "arm_b", transforms = ["Tx(l)", "Rz(0.2)"] }
[[loop]]
name = "rod"
kind = "distance"
length = "rod"
a = { body = "arm_a", transforms = ["Tx(0.1)"] }
b = { body = "arm_c", transforms = ["Tz(0.2)"] }
[[loop]]
name = "plane"
kind = "point_in_plane"
components = ["x"]
frame = "a"
a = { body = "slider" }
b = { body = "arm_c", transforms = ["Tz(0.2)"] }
[[loop]]
name = "gear"
kind = "coupling"
a = "g"
b = "a1"
ratio = "ratio"
offset = 0.1
"#;

#[test]
fn graph_derivation_matches_the_expanded_one() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for path in ["models/five_bar.toml", "models/stewart_6ups.toml"] {
        let source = std::fs::read_to_string(root.join(path)).unwrap();
        for form in [Form::BodyByBody, Form::Recursive, Form::Local] {
            compare(path, &source, form);
        }
    }
    // A weld loop (the closure of the UR5's task frame on its flange): its rotation rows, their G by the chain rule and their
    // gamma against the expanded reference.
    let ur5 = std::fs::read_to_string(root.join("models/ur5.toml")).unwrap();
    compare("models/ur5.toml", &ur5, Form::Recursive);
    for form in [Form::BodyByBody, Form::Recursive, Form::Local] {
        compare("<4-link chain>", CHAIN, form);
    }
    // The joints' own forces: springs with rest values, dampers, armatures (M's diagonal and
    // psi; the reference takes the springs' force as -∂Pi/∂X of their potential).
    let springs = std::fs::read_to_string(root.join("models/spring_pendulum.toml")).unwrap();
    for form in [Form::BodyByBody, Form::Recursive, Form::Local] {
        compare("models/spring_pendulum.toml", &springs, form);
    }
    // The other loop kinds: a hinge, a distance, a point in a plane, a coupling; and the
    // models with a distance loop and with a loop in a moving frame.
    compare("<loop kinds>", KINDS, Form::Recursive);
    for path in ["models/four_bar_rod.toml", "models/leg_four_bar.toml"] {
        let source = std::fs::read_to_string(root.join(path)).unwrap();
        compare(path, &source, Form::Recursive);
    }
    // Polynomial couplings between expressions of the coordinates (a joint's, a fixed tendon's
    // length), one coefficient a parameter, and a coordinate held at a constant.
    let path = "codegen/tests/import/couplings.toml";
    let source = std::fs::read_to_string(root.join(path)).unwrap();
    let poly = "poly = [0.1, 0.5, 0.3, 0.2, 0.1]";
    assert!(source.contains(poly), "{path}: {poly}");
    let source = source.replace(poly, "poly = [0.1, 0.5, \"c2\", 0.2, 0.1]")
        + "\n[parameters]\nc2 = { value = 0.3, unit = \"1\" }\n";
    compare(path, &source, Form::Recursive);
}
