//! `rbss bench solvers`: every solver call of a robot timed beside the generated kernels it
//! calls, in one run, as the ratio `ns_per_call / kernels_ns` (issue 8's table).
//!
//! - The state: the model's home assembly, its outputs moved by a small step (`1e-3` in every
//!   output, alternating in sign) for the warm solves; output rates and accelerations of a
//!   fixed pattern. Every robot has a home, so every robot gets a table.
//! - `kernels_ns`: the solver runs once on a [`Counting`] wrapper of the robot, which counts
//!   how often each kernel is called; each kernel is then timed alone at the solver's state and
//!   `kernels_ns = Σ calls × ns`. The ratio is what the solver costs over the code generated
//!   for it: 1 would be a solver that does nothing but call its kernels.
//! - Timing: batches of calls sized to ~1 ms, the median over batches of the time per call
//!   (`std::hint::black_box` on inputs and results).

use std::cell::Cell;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use rbss_runtime::{
    Baumgarte, Data, Dynamics, DynamicsDerivatives, Kernels, Model, Structure,
    forward_acceleration, forward_dynamics, forward_kinematics, forward_velocity,
    inverse_acceleration, inverse_dynamics, inverse_dynamics_full, inverse_kinematics,
    inverse_velocity,
};

/// The kernels a solver may call, in the order of the counters.
const KERNELS: [&str; 12] = [
    "constraints",
    "jacobian",
    "jacobian_p",
    "jacobian_ik",
    "gamma",
    "constraints_jacobian_ik",
    "constraints_jacobian_p",
    "mass_matrix",
    "psi",
    "energy",
    "dynamics_terms",
    "dynamics_derivatives",
];

/// A robot whose kernel calls are counted (index into `KERNELS`).
#[derive(Debug)]
pub struct Counting<K> {
    inner: K,
    calls: Cell<[u64; 12]>,
}

impl<K> Counting<K> {
    pub fn new(inner: K) -> Self {
        Self {
            inner,
            calls: Cell::new([0; 12]),
        }
    }
    fn hit(&self, k: usize) {
        let mut c = self.calls.get();
        c[k] += 1;
        self.calls.set(c);
    }
    /// Calls per kernel since the last reset, and resets.
    pub fn take(&self) -> [u64; 12] {
        self.calls.replace([0; 12])
    }
}

impl<K: Kernels<N, M>, const N: usize, const M: usize> Kernels<N, M> for Counting<K> {
    const IK_BLOCK_ORDER: usize = K::IK_BLOCK_ORDER;
    fn structure(&self) -> &'static Structure {
        self.inner.structure()
    }
    // The generated solves are not kernels (they evaluate nothing of the model): not counted.
    fn ik_block_solve(
        &self,
        block: usize,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        outputs: bool,
        x: &mut [f64; N],
    ) -> Option<[f64; 2]> {
        self.inner.ik_block_solve(block, g, rhs, outputs, x)
    }
    fn forward_rates_solve(
        &self,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        actuated: bool,
        exact: bool,
        x: &mut [f64; N],
    ) -> Option<[f64; 2]> {
        self.inner.forward_rates_solve(g, rhs, actuated, exact, x)
    }
    fn forward_rates_keep(
        &self,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        exact: bool,
        x: &mut [f64; N],
        store: &mut [f64],
    ) -> Option<([f64; 2], bool)> {
        self.inner.forward_rates_keep(g, rhs, exact, x, store)
    }
    fn forward_rates_chord(&self, store: &[f64], rhs: &[f64; M], x: &mut [f64; N]) -> Option<()> {
        self.inner.forward_rates_chord(store, rhs, x)
    }
    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
        self.hit(0);
        self.inner.constraints(x, f)
    }
    fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.hit(1);
        self.inner.jacobian(x, g)
    }
    fn jacobian_p(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.hit(2);
        self.inner.jacobian_p(x, g)
    }
    fn jacobian_ik(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.hit(3);
        self.inner.jacobian_ik(x, g)
    }
    fn gamma(&self, x: &[f64; N], xdot: &[f64; N], gamma: &mut [f64; M]) {
        self.hit(4);
        self.inner.gamma(x, xdot, gamma)
    }
    fn constraints_jacobian_ik(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
        self.hit(5);
        self.inner.constraints_jacobian_ik(x, f, g)
    }
    fn constraints_jacobian_p(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
        self.hit(6);
        self.inner.constraints_jacobian_p(x, f, g)
    }
}

impl<K: Dynamics<N, M>, const N: usize, const M: usize> Dynamics<N, M> for Counting<K> {
    fn mass_blocks(&self) -> &'static [&'static [usize]] {
        self.inner.mass_blocks()
    }
    fn mass_matrix(&self, x: &[f64; N], out: &mut [[f64; N]; N]) {
        self.hit(7);
        self.inner.mass_matrix(x, out)
    }
    fn psi(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; N]) {
        self.hit(8);
        self.inner.psi(x, xdot, out)
    }
    fn energy(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; 2]) {
        self.hit(9);
        self.inner.energy(x, xdot, out)
    }
    fn dynamics_terms(
        &self,
        x: &[f64; N],
        xdot: &[f64; N],
        g: &mut [[f64; M]; N],
        gamma: &mut [f64; M],
        mass: &mut [[f64; N]; N],
        psi: &mut [f64; N],
    ) {
        self.hit(10);
        self.inner.dynamics_terms(x, xdot, g, gamma, mass, psi)
    }
    // The generated solve is not a kernel (it evaluates nothing of the model): not counted.
    fn forward_dynamics_solve(
        &self,
        g: &[[f64; M]; N],
        mass: &[[f64; N]; N],
        force: &[f64; N],
        gamma: &[f64; M],
        xddot: &mut [f64; N],
        lambda: &mut [f64; M],
    ) -> Option<rbss_runtime::SolveConditioning> {
        self.inner
            .forward_dynamics_solve(g, mass, force, gamma, xddot, lambda)
    }
    #[allow(clippy::too_many_arguments)]
    fn inverse_dynamics_solve(
        &self,
        g: &[[f64; M]; N],
        mass: &[[f64; N]; N],
        psi: &[f64; N],
        xddot: &[f64; N],
        q_forces: Option<&[f64; N]>,
        u: &mut [f64],
        lambda: &mut [f64; M],
    ) -> Option<rbss_runtime::SolveConditioning> {
        self.inner
            .inverse_dynamics_solve(g, mass, psi, xddot, q_forces, u, lambda)
    }
}

impl<K: DynamicsDerivatives<N, M>, const N: usize, const M: usize> DynamicsDerivatives<N, M>
    for Counting<K>
{
    #[allow(clippy::too_many_arguments)]
    fn dynamics_derivatives(
        &self,
        x: &[f64; N],
        xdot: &[f64; N],
        xddot: &[f64; N],
        lambda: &[f64; M],
        dr_dx: &mut [[f64; N]; N],
        dr_dxdot: &mut [[f64; N]; N],
        dc_dx: &mut [[f64; M]; N],
        dc_dxdot: &mut [[f64; M]; N],
    ) {
        self.hit(11);
        self.inner
            .dynamics_derivatives(x, xdot, xddot, lambda, dr_dx, dr_dxdot, dc_dx, dc_dxdot)
    }
}

/// One row of the table.
#[derive(Debug, Clone)]
pub struct Row {
    pub solver: &'static str,
    pub ns_per_call: f64,
    pub kernels_ns: f64,
    /// The kernel calls the solver makes, e.g. `2 constraints_jacobian_ik`.
    pub calls: String,
}

impl Row {
    pub fn ratio(&self) -> f64 {
        self.ns_per_call / self.kernels_ns
    }
}

/// Median time per call of `f` in ns: batches of ~`batch_ns`, `batches` of them.
///
/// With `RBSS_BENCH_CALLS=n` in the environment, one batch of exactly `n` calls instead, no
/// calibration: for counting instructions under callgrind (`bench/instructions.sh`), where the
/// count per call is what is compared and the time means nothing.
pub fn time_ns(mut f: impl FnMut(), batches: usize, batch_ns: f64) -> f64 {
    if let Some(n) = fixed_calls() {
        let t = Instant::now();
        for _ in 0..n {
            f();
        }
        return t.elapsed().as_nanos() as f64 / n as f64;
    }
    // Calibrate the batch size.
    let mut reps = 1usize;
    loop {
        let t = Instant::now();
        for _ in 0..reps {
            f();
        }
        let ns = t.elapsed().as_nanos() as f64;
        if ns >= batch_ns / 4.0 || reps >= 1 << 24 {
            reps = ((reps as f64) * batch_ns / ns.max(1.0)).ceil().max(1.0) as usize;
            break;
        }
        reps *= 4;
    }
    let mut per_call: Vec<f64> = (0..batches.max(1))
        .map(|_| {
            let t = Instant::now();
            for _ in 0..reps {
                f();
            }
            t.elapsed().as_nanos() as f64 / reps as f64
        })
        .collect();
    per_call.sort_by(f64::total_cmp);
    per_call[per_call.len() / 2]
}

/// `RBSS_BENCH_CALLS`, when set to a positive number (see [`time_ns`]).
fn fixed_calls() -> Option<usize> {
    std::env::var("RBSS_BENCH_CALLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&n: &usize| n > 0)
}

/// The state of the table: the home assembly, the warm-start point one small output step away,
/// and the output rates and accelerations.
struct State<const N: usize> {
    x0: [f64; N],
    o1: Vec<f64>,
    odot: Vec<f64>,
    oddot: Vec<f64>,
}

fn state<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
) -> Result<State<N>, String> {
    let s = model.structure();
    let mut d = Data::new(model);
    d.set_home(model);
    let o0: Vec<f64> = s.outputs.iter().map(|&j| s.home[j]).collect();
    // Assemble exactly at home's outputs (home is given to ~12 digits).
    inverse_kinematics(model, &mut d, &o0)
        .map_err(|e| format!("inverse kinematics at the home outputs: {e}"))?;
    let sign = |i: usize| if i.is_multiple_of(2) { 1.0 } else { -1.0 };
    let o1 = o0
        .iter()
        .enumerate()
        .map(|(i, v)| v + 1e-3 * sign(i))
        .collect();
    let odot = (0..o0.len()).map(|i| 0.1 * sign(i + 1)).collect();
    let oddot = (0..o0.len())
        .map(|i| 0.5 * sign(i) * (1.0 + i as f64 / 10.0))
        .collect();
    Ok(State {
        x0: d.x,
        o1,
        odot,
        oddot,
    })
}

/// Measures the table for one robot.
pub fn measure<K: Dynamics<N, M> + Clone, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    batches: usize,
) -> Result<Vec<Row>, String> {
    let st = state(model)?;
    fn err(what: &'static str) -> impl Fn(rbss_runtime::SolverError) -> String {
        move |e| format!("{what}: {e}")
    }
    let counting = Model::new(Counting::new(model.kernels().clone())).with_options(model.options);
    let s = model.structure();
    let bt = 1e6; // ns per batch

    // The solved state at o1 (x1, xdot, xddot) and U there. A robot with passive degrees of
    // freedom has no inverse dynamics (nor forward kinematics, velocity, acceleration): its
    // state from the outputs alone, and forward dynamics under U = 0.
    let full = s.fully_actuated();
    let mut d1 = Data::new(model);
    d1.x = st.x0;
    let u1: Vec<f64> = if full {
        inverse_dynamics_full(model, &mut d1, &st.o1, &st.odot, &st.oddot, None)
            .map_err(err("inverse dynamics at the table's state"))?;
        d1.u().to_vec()
    } else {
        inverse_kinematics(model, &mut d1, &st.o1)
            .map_err(err("inverse kinematics at the table's state"))?;
        inverse_velocity(model, &mut d1, &st.odot)
            .map_err(err("inverse velocity at the table's state"))?;
        inverse_acceleration(model, &mut d1, &st.oddot)
            .map_err(err("inverse acceleration at the table's state"))?;
        vec![0.0; s.actuated.len()]
    };
    let q1: Vec<f64> = s.actuated.iter().map(|&j| d1.x[j]).collect();
    let qdot1: Vec<f64> = s.actuated.iter().map(|&j| d1.xdot[j]).collect();
    let qddot1: Vec<f64> = s.actuated.iter().map(|&j| d1.xddot[j]).collect();

    // Kernel times at the solved state.
    let k = model.kernels();
    let (x1, v1) = (d1.x, d1.xdot);
    let mut f = [0.0; M];
    let mut g = [[0.0; M]; N];
    let mut gam = [0.0; M];
    let mut mass = [[0.0; N]; N];
    let mut psi = [0.0; N];
    let mut e2 = [0.0; 2];
    let mut kernel_ns = [0.0_f64; 12];
    kernel_ns[0] = time_ns(
        || k.constraints(black_box(&x1), black_box(&mut f)),
        batches,
        bt,
    );
    kernel_ns[1] = time_ns(
        || k.jacobian(black_box(&x1), black_box(&mut g)),
        batches,
        bt,
    );
    kernel_ns[2] = time_ns(
        || k.jacobian_p(black_box(&x1), black_box(&mut g)),
        batches,
        bt,
    );
    kernel_ns[3] = time_ns(
        || k.jacobian_ik(black_box(&x1), black_box(&mut g)),
        batches,
        bt,
    );
    kernel_ns[4] = time_ns(
        || k.gamma(black_box(&x1), black_box(&v1), black_box(&mut gam)),
        batches,
        bt,
    );
    kernel_ns[5] = time_ns(
        || k.constraints_jacobian_ik(black_box(&x1), black_box(&mut f), black_box(&mut g)),
        batches,
        bt,
    );
    kernel_ns[6] = time_ns(
        || k.constraints_jacobian_p(black_box(&x1), black_box(&mut f), black_box(&mut g)),
        batches,
        bt,
    );
    kernel_ns[7] = time_ns(
        || k.mass_matrix(black_box(&x1), black_box(&mut mass)),
        batches,
        bt,
    );
    kernel_ns[8] = time_ns(
        || k.psi(black_box(&x1), black_box(&v1), black_box(&mut psi)),
        batches,
        bt,
    );
    kernel_ns[9] = time_ns(
        || k.energy(black_box(&x1), black_box(&v1), black_box(&mut e2)),
        batches,
        bt,
    );
    kernel_ns[10] = time_ns(
        || {
            k.dynamics_terms(
                black_box(&x1),
                black_box(&v1),
                black_box(&mut g),
                black_box(&mut gam),
                black_box(&mut mass),
                black_box(&mut psi),
            )
        },
        batches,
        bt,
    );

    type Call<'c, R, const N: usize, const M: usize> =
        Box<dyn FnMut(&Model<R, N, M>, &mut Data<N, M>) -> Result<(), String> + 'c>;
    // Each solver: its name, how to prepare a Data (outside the timing), and the call. The
    // same closures run on the counting model (once) and on the real one (timed).
    let mut rows = Vec::new();
    let mut run = |name: &'static str,
                   prep: &dyn Fn(&mut Data<N, M>),
                   mut call_c: Call<'_, Counting<K>, N, M>,
                   mut call: Call<'_, K, N, M>|
     -> Result<(), String> {
        let mut dc = Data::new(&counting);
        prep(&mut dc);
        counting.kernels().take();
        call_c(&counting, &mut dc)?;
        let calls = counting.kernels().take();
        // Each call starts from the same state: `prep` writes the solver's inputs in `Data`
        // (x, and the rates where the solver reads them); everything else is the solver's own
        // output or scratch.
        let mut d = Data::new(model);
        prep(&mut d);
        let ns = time_ns(
            || {
                prep(&mut d);
                let _ = black_box(call(model, &mut d));
            },
            batches,
            bt,
        );
        let kernels_ns: f64 = calls
            .iter()
            .zip(kernel_ns)
            .map(|(&c, t)| c as f64 * t)
            .sum();
        let list: Vec<String> = calls
            .iter()
            .zip(KERNELS)
            .filter(|(c, _)| **c > 0)
            .map(|(c, n)| format!("{c} {n}"))
            .collect();
        rows.push(Row {
            solver: name,
            ns_per_call: ns,
            kernels_ns,
            calls: list.join(" + "),
        });
        Ok(())
    };

    let at_x0 = |d: &mut Data<N, M>| d.x = st.x0;
    let solved = |d: &mut Data<N, M>| {
        d.x = d1.x;
        d.xdot = d1.xdot;
        d.xddot = d1.xddot;
    };
    macro_rules! both {
        (|$m:ident, $d:ident| $body:expr) => {
            (
                Box::new(|$m: &Model<Counting<K>, N, M>, $d: &mut Data<N, M>| $body),
                Box::new(|$m: &Model<K, N, M>, $d: &mut Data<N, M>| $body),
            )
        };
    }
    let (a, b) = both!(|m, d| inverse_kinematics(m, d, &st.o1)
        .map(|_| ())
        .map_err(err("ik_warm")));
    run("ik_warm", &at_x0, a, b)?;
    if full {
        let (a, b) = both!(|m, d| forward_kinematics(m, d, &q1)
            .map(|_| ())
            .map_err(err("fk_warm")));
        run("fk_warm", &at_x0, a, b)?;
    }
    let (a, b) = both!(|m, d| inverse_velocity(m, d, &st.odot)
        .map(|_| ())
        .map_err(err("inverse_velocity")));
    run("inverse_velocity", &solved, a, b)?;
    let (a, b) = both!(|m, d| inverse_acceleration(m, d, &st.oddot)
        .map(|_| ())
        .map_err(err("inverse_acceleration")));
    run("inverse_acceleration", &solved, a, b)?;
    if full {
        let (a, b) = both!(|m, d| forward_velocity(m, d, &qdot1)
            .map(|_| ())
            .map_err(err("forward_velocity")));
        run("forward_velocity", &solved, a, b)?;
        let (a, b) = both!(|m, d| forward_acceleration(m, d, &qddot1)
            .map(|_| ())
            .map_err(err("forward_acceleration")));
        run("forward_acceleration", &solved, a, b)?;
        let (a, b) = both!(|m, d| inverse_dynamics(m, d, None)
            .map(|_| ())
            .map_err(err("inverse_dynamics")));
        run("inverse_dynamics", &solved, a, b)?;
    }
    let (a, b) = both!(|m, d| forward_dynamics(m, d, &u1, None, Baumgarte::NONE)
        .map(|_| ())
        .map_err(err("forward_dynamics")));
    run("forward_dynamics", &solved, a, b)?;
    if full {
        let (a, b) = both!(
            |m, d| inverse_dynamics_full(m, d, &st.o1, &st.odot, &st.oddot, None)
                .map(|_| ())
                .map_err(err("id_sample"))
        );
        run("id_sample", &at_x0, a, b)?;
    }
    Ok(rows)
}

/// The rows a robot with passive degrees of freedom has not, and why (`None` when it has them
/// all).
pub fn missing_rows(s: &rbss_runtime::Structure) -> Option<String> {
    (!s.fully_actuated()).then(|| {
        format!(
            "{}: {} degree(s) of freedom, {} actuated: no fk_warm, forward_velocity, \
             forward_acceleration, inverse_dynamics or id_sample rows (they need every degree \
             of freedom actuated); forward_dynamics runs under U = 0",
            s.name,
            s.coordinates.len().saturating_sub(s.constraints.len()),
            s.actuated.len()
        )
    })
}

/// The CSV (`solver,ns_per_call,kernels_ns,ratio,kernel_calls`).
pub fn csv(rows: &[Row]) -> String {
    let mut s = String::from("solver,ns_per_call,kernels_ns,ratio,kernel_calls\n");
    for r in rows {
        s += &format!(
            "{},{:.1},{:.1},{:.2},{}\n",
            r.solver,
            r.ns_per_call,
            r.kernels_ns,
            r.ratio(),
            r.calls
        );
    }
    s
}

/// The same as a Markdown table.
pub fn table(robot: &str, rows: &[Row]) -> String {
    let mut s = String::from(
        "| robot | solver | ns per call | kernels ns | ratio | kernel calls |\n|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s += &format!(
            "| {robot} | {} | {:.0} | {:.0} | {:.2} | {} |\n",
            r.solver,
            r.ns_per_call,
            r.kernels_ns,
            r.ratio(),
            r.calls
        );
    }
    s
}

/// `rbss bench solvers --model NAME --out DIR` (or `--model-file PATH`) on `model`.
pub fn command<K: Dynamics<N, M> + Clone, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    out: &Path,
    batches: usize,
) -> Result<(), String> {
    let rows = measure(model, batches)?;
    crate::create_output_dir(out)?;
    let path = out.join("solvers.csv");
    // Through a temporary: a failure leaves the old file, not half of a new one.
    crate::output::write_file(&path, |f| {
        std::io::Write::write_all(f, csv(&rows).as_bytes())
            .map_err(|e| format!("{}: cannot write: {e}", path.display()))
    })?;
    crate::outp!("{}", table(model.structure().name, &rows));
    if let Some(note) = missing_rows(model.structure()) {
        crate::outln!("{note}");
    }
    crate::outln!("wrote {}", path.display());
    Ok(())
}
