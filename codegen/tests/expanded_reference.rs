//! The named-intermediate derivation (`rbss_codegen::derive`, what the kernels are generated
//! from) against the fully expanded one done independently with symbolica
//! (`rbss_codegen::expanded`): `f`, `G`, `gamma`, `M` and `psi` of the five-bar and the paper's
//! 6-UPS at random states. The two share only the parsed model: one builds frames recursively
//! and takes the dynamics body by body (Newton-Euler projected on the Jacobians), the other
//! expands the frames and differentiates `T` as Lagrange's equations are written.
//!
//! The only test in this binary: it runs symbolica (one thread per user), behind the lock.

// Matrices over index pairs read best with explicit indices.
#![allow(clippy::needless_range_loop)]

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

fn compare(path: &str) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let source = std::fs::read_to_string(root.join(path)).unwrap();
    let model = rbss_codegen::parse::parse_model(path, &source).unwrap_or_else(|e| panic!("{e:?}"));
    let n = model.coordinates.len();
    let np = model.parameters.len();
    let frozen = vec![false; np];
    let d = rbss_codegen::derive::derive(&model, true, &frozen, &mut |_| {})
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

#[test]
fn graph_derivation_matches_the_expanded_one() {
    compare("models/five_bar.toml");
    compare("models/stewart_6ups.toml");
}
