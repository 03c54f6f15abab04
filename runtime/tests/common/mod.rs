//! Shared test fixtures: the hand-written five-bar robot and a seeded generator.

#![allow(dead_code)]

pub mod dd;
pub mod five_bar;

/// Marsaglia's xorshift64: seeded, reproducible, no dependency.
pub struct XorShift(pub u64);

impl XorShift {
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
}

/// First and second time derivatives at the middle of five samples `xs[k] = x(t + (k - 2) h)`,
/// by fourth-order central differences.
pub fn central_4th<const N: usize>(xs: &[[f64; N]; 5], h: f64) -> ([f64; N], [f64; N]) {
    let d1 = core::array::from_fn(|j| {
        (-xs[4][j] + 8.0 * xs[3][j] - 8.0 * xs[1][j] + xs[0][j]) / (12.0 * h)
    });
    let d2 = core::array::from_fn(|j| {
        (-xs[4][j] + 16.0 * xs[3][j] - 30.0 * xs[2][j] + 16.0 * xs[1][j] - xs[0][j])
            / (12.0 * h * h)
    });
    (d1, d2)
}

/// A random pose of the 6-UPS's platform near home: x, y within ±0.1 m, z in [0.89, 0.99] m,
/// each rotation within ±0.15 rad (reachable, away from singularities).
pub fn random_stewart_pose(rng: &mut XorShift) -> [f64; 6] {
    [
        rng.range(-0.1, 0.1),
        rng.range(-0.1, 0.1),
        rng.range(0.89, 0.99),
        rng.range(-0.15, 0.15),
        rng.range(-0.15, 0.15),
        rng.range(-0.15, 0.15),
    ]
}

/// One RK4 step of `dt` of the integrator (`Simulator`, `Method::Rk4`, `stab`) from `(x0, v0)`
/// with the control forces `u` held: the simulator's start (projected onto the constraints by
/// `Simulator::new`) and the state after the step, each `(X, Ẋ)`.
#[allow(clippy::type_complexity)]
pub fn simulator_rk4_step<
    K: rbss_runtime::tasks::Simulate<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &rbss_runtime::Model<K, N, M>,
    x0: &[f64; N],
    v0: &[f64; N],
    u: &[f64],
    dt: f64,
    stab: rbss_runtime::integrate::Stabilization,
) -> (([f64; N], [f64; N]), ([f64; N], [f64; N])) {
    use rbss_runtime::integrate::{IntegrateOptions, Method, Simulator};
    let mut data = rbss_runtime::Data::new(model);
    let mut sim = Simulator::new(
        model,
        &mut data,
        0.0,
        x0,
        v0,
        IntegrateOptions::new(Method::Rk4 { dt }, stab),
    )
    .unwrap();
    let start = (*sim.x(), *sim.xdot());
    let mut control = |_t: f64, _x: &[f64; N], _v: &[f64; N], uu: &mut [f64]| {
        uu.copy_from_slice(u);
        Ok(())
    };
    sim.step(model, &mut data, dt, &mut control).unwrap();
    (start, (*sim.x(), *sim.xdot()))
}
