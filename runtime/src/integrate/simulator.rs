//! The simulator: the state, the stages, RK4 and the adaptive pairs' steps (with their error
//! estimate, step-size control and `HINIT`), the right-hand side (the control, then forward
//! dynamics) and the stabilisations.

use super::options::{
    IntegrateError, IntegrateOptions, IntegrateStats, Method, Stabilization, StepControl, validate,
};
use super::tableau::{DOP853, DOPRI5, Pair, SAFE, STAGES};
use crate::algorithm::forward_dynamics::Report;
use crate::algorithm::input::max_abs;
use crate::algorithm::{
    Baumgarte, forward_kinematics, forward_velocity, project_position, project_velocity,
};
use crate::data::Data;
use crate::error::SolverError;
use crate::model::Model;
use crate::plan::mat_vec;
use crate::tasks::Simulate;

/// A simulation in progress: the state `(t, X, Ẋ)`, the integrator's memory and statistics.
///
/// All buffers are fixed-size arrays: [`Simulator::step`] does not allocate. Use one `Data`
/// for the simulator's own solves and, if the control callback solves anything (inverse
/// kinematics and dynamics of a reference motion, say), another one captured by the callback.
#[derive(Debug, Clone)]
pub struct Simulator<const N: usize, const M: usize> {
    t: f64,
    /// The clock, kept without accumulated rounding: RK4's full steps land on
    /// `t_origin + n_fixed dt` (`t_origin` the start or the last `t_end` landed on); DOPRI5's
    /// `t += h` carries the compensation `t_comp` of Kahan's summation. (Issue 12: `t += dt`
    /// drifts by 2e-13 s over 20 000 steps of 1e-4 s, a relative error of 6e-13 in the control
    /// `U(t)` of a feed-forward run.)
    t_origin: f64,
    n_fixed: u64,
    t_comp: f64,
    /// RK4: the compensations of Kahan's summation of the state update `x += h Σ b_j k_j`
    /// (zero after a projection, which replaces the state).
    cx: [f64; N],
    cv: [f64; N],
    x: [f64; N],
    xdot: [f64; N],
    options: IntegrateOptions,
    stats: IntegrateStats,
    /// The state components integrated: all N (`0..N`), or the actuated ones (coordinate
    /// partitioning), in the first `n_active` entries.
    active: [usize; N],
    n_active: usize,
    /// DOPRI5, DOP853: the next step size (0 = not chosen yet), the previous error (PI), and whether
    /// the previous attempt was rejected.
    h: f64,
    err_prev: f64,
    rejected_last: bool,
    /// `kx[0]`, `kv[0]` hold the derivative at the current state (FSAL).
    fsal: bool,
    /// Stage derivatives: of `X` (the stage velocity) and of `Ẋ` (the acceleration).
    kx: [[f64; STAGES]; N],
    kv: [[f64; STAGES]; N],
    /// The stage state.
    xs: [f64; N],
    vs: [f64; N],
    /// Coordinate partitioning: the full state at the last stage evaluation.
    x_full: [f64; N],
    v_full: [f64; N],
    /// Control forces of the current evaluation (first `N - M`).
    u: [f64; N],
}

impl<const N: usize, const M: usize> Simulator<N, M> {
    /// Starts a simulation at time `t0` from `x0`, `xdot0`, which are first made consistent:
    /// `x0` projected onto `f(X) = 0` and `xdot0` onto `G Ẋ = 0` ([`project_position`],
    /// [`project_velocity`]); the size of both corrections is in [`Simulator::stats`].
    ///
    /// Errors: `InvalidOptions` for a non-positive or non-finite step, tolerance or step limit,
    /// or a non-finite `t0`; `Solver` when the projection fails (a NaN, a singular `G`, or a
    /// state too far from the manifold).
    pub fn new<K: Simulate<N, M>>(
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
        t0: f64,
        x0: &[f64; N],
        xdot0: &[f64; N],
        options: IntegrateOptions,
    ) -> Result<Self, IntegrateError> {
        validate(&options)?;
        if !t0.is_finite() {
            return Err(IntegrateError::InvalidOptions { what: "t0" });
        }
        let solver = |error| IntegrateError::Solver { t: t0, error };
        if options.stabilization == Stabilization::CoordinatePartitioning {
            // The actuated coordinates are the independent ones: all the degrees of freedom.
            model
                .structure()
                .require_actuated("coordinate partitioning")
                .map_err(solver)?;
        }
        data.x = *x0;
        let rep = project_position(model, data).map_err(solver)?;
        let initial_correction = max_diff(&data.x, x0);
        data.xdot = *xdot0;
        let repv = project_velocity(model, data).map_err(solver)?;
        let initial_velocity_correction = max_diff(&data.xdot, xdot0);

        let mut active = [0; N];
        let mut n_active = N;
        if options.stabilization == Stabilization::CoordinatePartitioning {
            let act = model.structure().actuated;
            n_active = act.len();
            active[..n_active].copy_from_slice(act);
        } else {
            for (i, a) in active.iter_mut().enumerate() {
                *a = i;
            }
        }
        let h = match options.method {
            Method::Dopri5 { h_init, .. } | Method::Dop853 { h_init, .. } => h_init,
            Method::Rk4 { dt } => dt,
        };
        Ok(Self {
            t: t0,
            t_origin: t0,
            n_fixed: 0,
            t_comp: 0.0,
            cx: [0.0; N],
            cv: [0.0; N],
            x: data.x,
            xdot: data.xdot,
            options,
            stats: IntegrateStats {
                newton_iterations: rep.iterations,
                max_violation: rep.residual,
                max_velocity_violation: repv.residual,
                initial_correction,
                initial_velocity_correction,
                h_min: f64::INFINITY,
                ..IntegrateStats::default()
            },
            active,
            n_active,
            h,
            err_prev: 1e-4,
            rejected_last: false,
            fsal: false,
            kx: [[0.0; STAGES]; N],
            kv: [[0.0; STAGES]; N],
            xs: [0.0; N],
            vs: [0.0; N],
            x_full: data.x,
            v_full: data.xdot,
            u: [0.0; N],
        })
    }

    /// The current time (s).
    pub fn t(&self) -> f64 {
        self.t
    }

    /// The current coordinates `X` (N).
    pub fn x(&self) -> &[f64; N] {
        &self.x
    }

    /// The current velocities `Ẋ` (N).
    pub fn xdot(&self) -> &[f64; N] {
        &self.xdot
    }

    /// The statistics so far.
    pub fn stats(&self) -> &IntegrateStats {
        &self.stats
    }

    /// The settings.
    pub fn options(&self) -> &IntegrateOptions {
        &self.options
    }

    /// Integrates until `t_end`, calling `observer` after every accepted step; returns the
    /// statistics. `control(t, X, Ẋ, U)` must write the `N - M` control forces (`U` starts
    /// zeroed). Errors: `InvalidOptions` if `t_end` is not finite (a NaN `t_end` would
    /// otherwise end the loop at once and report success); `t_end` at or before the current time
    /// takes no step.
    pub fn run<K, C, O>(
        &mut self,
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
        t_end: f64,
        control: &mut C,
        mut observer: O,
    ) -> Result<IntegrateStats, IntegrateError>
    where
        K: Simulate<N, M>,
        C: FnMut(f64, &[f64; N], &[f64; N], &mut [f64]) -> Result<(), SolverError> + ?Sized,
        O: FnMut(&Self),
    {
        if !t_end.is_finite() {
            return Err(IntegrateError::InvalidOptions {
                what: "t_end (not finite)",
            });
        }
        while self.t < t_end {
            self.step(model, data, t_end, control)?;
            observer(self);
        }
        Ok(self.stats)
    }

    /// Takes one accepted step towards `t_end`, never past it (DOPRI5 and DOP853 may reject attempts
    /// first). Errors: `InvalidOptions` if `t_end` is not after the current time or not
    /// finite; otherwise see [`IntegrateError`].
    pub fn step<K, C>(
        &mut self,
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
        t_end: f64,
        control: &mut C,
    ) -> Result<(), IntegrateError>
    where
        K: Simulate<N, M>,
        C: FnMut(f64, &[f64; N], &[f64; N], &mut [f64]) -> Result<(), SolverError> + ?Sized,
    {
        if !t_end.is_finite() || t_end <= self.t {
            return Err(IntegrateError::InvalidOptions {
                what: "t_end (not after the current time)",
            });
        }
        let h = match self.options.method {
            Method::Rk4 { dt } => {
                self.check_steps()?;
                let rest = t_end - self.t;
                // Land on t_end (and count from there); avoid a sliver of a last step.
                if rest <= dt * (1.0 + 1e-9) {
                    self.rk4(model, data, control, rest, t_end)?;
                    self.t_origin = t_end;
                    self.n_fixed = 0;
                    rest
                } else {
                    let t_new = self.t_origin + (self.n_fixed + 1) as f64 * dt;
                    self.rk4(model, data, control, dt, t_new)?;
                    self.n_fixed += 1;
                    dt
                }
            }
            method @ (Method::Dopri5 {
                rtol,
                atol,
                h_max,
                control: sc,
                ..
            }
            | Method::Dop853 {
                rtol,
                atol,
                h_max,
                control: sc,
                ..
            }) => {
                let pair = match method {
                    Method::Dop853 { .. } => &DOP853,
                    _ => &DOPRI5,
                };
                let tol = Tolerances::new(rtol, atol, h_max, sc);
                self.embedded(pair, model, data, control, t_end, tol)?
            }
        };
        self.stats.steps += 1;
        self.stats.h_min = self.stats.h_min.min(h);
        self.stats.h_max = self.stats.h_max.max(h);
        self.after_step(model, data)
    }

    fn check_steps(&self) -> Result<(), IntegrateError> {
        let taken = self.stats.steps + self.stats.rejected;
        if taken >= self.options.max_steps {
            return Err(IntegrateError::MaxSteps {
                t: self.t,
                steps: taken,
            });
        }
        Ok(())
    }

    /// Evaluates the right-hand side at `(t, xs, vs)` into stage `s` of `kx`, `kv`.
    fn eval<K, C>(
        &mut self,
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
        control: &mut C,
        t: f64,
        s: usize,
    ) -> Result<(), IntegrateError>
    where
        K: Simulate<N, M>,
        C: FnMut(f64, &[f64; N], &[f64; N], &mut [f64]) -> Result<(), SolverError> + ?Sized,
    {
        let solver = |error| IntegrateError::Solver { t, error };
        let n_act = model.structure().actuated.len();
        let gains = match self.options.stabilization {
            Stabilization::Baumgarte(b) => b,
            _ => Baumgarte::NONE,
        };
        if self.options.stabilization == Stabilization::CoordinatePartitioning {
            let (xs, vs) = (self.xs, self.vs);
            self.recover(model, data, t, &xs, &vs)?;
        } else {
            data.x = self.xs;
            data.xdot = self.vs;
        }
        self.stats.rhs_evaluations += 1;
        let u = &mut self.u[..n_act];
        u.fill(0.0);
        control(t, &data.x, &data.xdot, u).map_err(|error| IntegrateError::Control { t, error })?;
        // The report is discarded: skip the exact condition number of S_c (its certification,
        // which decides `Singular`, is the same). Without constraints, `M Ẍ = F`.
        if M == 0 {
            crate::algorithm::forward_dynamics(model, data, u, None, gains).map_err(solver)?;
        } else {
            crate::algorithm::forward_dynamics::solve(
                model,
                data,
                u,
                None,
                gains,
                Report::Bound,
                crate::algorithm::forward_dynamics::Path::Auto,
            )
            .map_err(solver)?;
        }
        for i in 0..N {
            self.kx[i][s] = data.xdot[i];
            self.kv[i][s] = data.xddot[i];
        }
        Ok(())
    }

    /// Coordinate partitioning: the full `X, Ẋ` for the actuated `q, q̇` taken from `xq`,
    /// `vq`, by forward kinematics warm-started from the accepted state and forward velocity,
    /// into `data.x`, `data.xdot` and `x_full`, `v_full`.
    fn recover<K: Simulate<N, M>>(
        &mut self,
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
        t: f64,
        xq: &[f64; N],
        vq: &[f64; N],
    ) -> Result<(), IntegrateError> {
        let solver = |error| IntegrateError::Solver { t, error };
        let act = model.structure().actuated;
        let n_act = act.len();
        let mut q = [0.0; N];
        for (qa, &j) in q.iter_mut().zip(act) {
            *qa = xq[j];
        }
        data.x = self.x;
        let rep = forward_kinematics(model, data, &q[..n_act]).map_err(solver)?;
        self.stats.newton_iterations += rep.iterations;
        for (qa, &j) in q.iter_mut().zip(act) {
            *qa = vq[j];
        }
        forward_velocity(model, data, &q[..n_act]).map_err(solver)?;
        self.x_full = data.x;
        self.v_full = data.xdot;
        Ok(())
    }

    /// The step's result `xs, vs = y + h Σ_j b[j] k_j` by compensated (Kahan) summation across
    /// steps: the rounding of each update, `ulp(x) / 2` per step, is carried into the next one
    /// instead of accumulating over thousands of fixed steps (issue 12: at `dt` = 5e-5 the plain
    /// update's rounding, amplified by the open-loop instability of a feed-forward run, was the
    /// error floor of the paper's round trip).
    fn update_compensated(&mut self, h: f64, b: &[f64]) {
        self.xs = self.x;
        self.vs = self.xdot;
        for &i in &self.active[..self.n_active] {
            let (mut dx, mut dv) = (0.0, 0.0);
            for (j, &c) in b.iter().enumerate() {
                dx += c * self.kx[i][j];
                dv += c * self.kv[i][j];
            }
            let y = h * dx - self.cx[i];
            self.xs[i] = self.x[i] + y;
            self.cx[i] = (self.xs[i] - self.x[i]) - y;
            let y = h * dv - self.cv[i];
            self.vs[i] = self.xdot[i] + y;
            self.cv[i] = (self.vs[i] - self.xdot[i]) - y;
        }
    }

    /// Sets the stage state `xs, vs = y + h Σ_j coef[j] k_j` over the active components.
    fn stage_state(&mut self, h: f64, coef: &[f64]) {
        self.xs = self.x;
        self.vs = self.xdot;
        for &i in &self.active[..self.n_active] {
            let (mut dx, mut dv) = (0.0, 0.0);
            for (j, &c) in coef.iter().enumerate() {
                if c != 0.0 {
                    dx += c * self.kx[i][j];
                    dv += c * self.kv[i][j];
                }
            }
            self.xs[i] = self.x[i] + h * dx;
            self.vs[i] = self.xdot[i] + h * dv;
        }
    }

    fn rk4<K, C>(
        &mut self,
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
        control: &mut C,
        h: f64,
        t_new: f64,
    ) -> Result<(), IntegrateError>
    where
        K: Simulate<N, M>,
        C: FnMut(f64, &[f64; N], &[f64; N], &mut [f64]) -> Result<(), SolverError> + ?Sized,
    {
        let t = self.t;
        self.stage_state(h, &[]);
        self.eval(model, data, control, t, 0)?;
        self.stage_state(h, &[0.5]);
        self.eval(model, data, control, t + 0.5 * h, 1)?;
        self.stage_state(h, &[0.0, 0.5]);
        self.eval(model, data, control, t + 0.5 * h, 2)?;
        self.stage_state(h, &[0.0, 0.0, 1.0]);
        self.eval(model, data, control, t_new, 3)?;
        // b = (1, 2, 2, 1) / 6: exact weights, one rounding of h / 6.
        self.update_compensated(h / 6.0, &[1.0, 2.0, 2.0, 1.0]);
        self.t = t_new;
        if self.options.stabilization == Stabilization::CoordinatePartitioning {
            let (xs, vs) = (self.xs, self.vs);
            self.recover(model, data, self.t, &xs, &vs)?;
            self.x = self.x_full;
            self.xdot = self.v_full;
            // Only the integrated (actuated) components carry a compensation; forward kinematics
            // returns them unchanged.
        } else {
            self.x = self.xs;
            self.xdot = self.vs;
        }
        self.fsal = false;
        Ok(())
    }

    /// After an accepted step: monitor the violation, then project if asked.
    fn after_step<K: Simulate<N, M>>(
        &mut self,
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
    ) -> Result<(), IntegrateError> {
        let solver = |t, error| IntegrateError::Solver { t, error };
        if self.x.iter().chain(&self.xdot).any(|v| !v.is_finite()) {
            return Err(solver(
                self.t,
                SolverError::NonFinite {
                    what: "state after a step",
                },
            ));
        }
        if self.options.monitor {
            let k = model.kernels();
            k.constraints(&self.x, &mut data.f);
            k.jacobian(&self.x, &mut data.g.data.0);
            mat_vec(&data.g, &self.xdot, &mut data.ws.rhs);
            let s = &mut self.stats;
            s.max_violation = s.max_violation.max(max_abs(&data.f));
            s.max_velocity_violation = s.max_velocity_violation.max(max_abs(&data.ws.rhs));
        }
        if self.options.stabilization == Stabilization::Projection {
            data.x = self.x;
            let rep = project_position(model, data).map_err(|e| solver(self.t, e))?;
            self.stats.newton_iterations += rep.iterations;
            data.xdot = self.xdot;
            project_velocity(model, data).map_err(|e| solver(self.t, e))?;
            self.x = data.x;
            self.xdot = data.xdot;
            self.fsal = false;
            self.cx = [0.0; N];
            self.cv = [0.0; N];
        }
        Ok(())
    }
}

/// The tolerances and controller of an adaptive run.
#[derive(Debug, Clone, Copy)]
struct Tolerances {
    rtol: f64,
    atol: f64,
    h_max: f64,
    /// The PI gain (0: the standard controller).
    beta: f64,
}

impl Tolerances {
    fn new(rtol: f64, atol: f64, h_max: f64, control: StepControl) -> Self {
        let beta = match control {
            StepControl::Standard => 0.0,
            StepControl::Pi { beta } => beta,
        };
        Self {
            rtol,
            atol,
            h_max,
            beta,
        }
    }
}

impl<const N: usize, const M: usize> Simulator<N, M> {
    /// One accepted step of the pair `pair`; returns its size.
    fn embedded<K, C>(
        &mut self,
        pair: &Pair,
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
        control: &mut C,
        t_end: f64,
        tol: Tolerances,
    ) -> Result<f64, IntegrateError>
    where
        K: Simulate<N, M>,
        C: FnMut(f64, &[f64; N], &[f64; N], &mut [f64]) -> Result<(), SolverError> + ?Sized,
    {
        let t = self.t;
        let s_end = pair.solution;
        // Stage S enters DOPRI5's error estimate, not DOP853's.
        let fsal_in_error = pair.e[s_end] != 0.0;
        if !self.fsal {
            self.stage_state(0.0, &[]);
            self.eval(model, data, control, t, 0)?;
            self.fsal = true;
        }
        if self.h <= 0.0 {
            self.h = self.initial_step(pair, model, data, control, tol)?;
        }
        let expo = pair.expo - pair.pi_weight * tol.beta;
        loop {
            self.check_steps()?;
            let mut h = self.h.min(tol.h_max);
            let last = t + 1.01 * h >= t_end;
            if last {
                h = t_end - t;
            }
            // Also catches a NaN step.
            if h.is_nan() || h <= 16.0 * f64::EPSILON * t.abs().max(f64::MIN_POSITIVE) {
                return Err(IntegrateError::StepSizeTooSmall { t, h });
            }
            for s in 1..=s_end {
                self.stage_state(h, pair.a[s]);
                if s < s_end || fsal_in_error {
                    self.eval(model, data, control, t + pair.c[s] * h, s)?;
                }
            }
            // xs, vs: the solution (stage S's argument).
            let err = self.error(pair, h, &tol);
            if !err.is_finite() {
                // Overflow in the trial stages: shrink hard and retry.
                self.h = h * pair.fac_min;
                self.rejected_last = true;
                self.stats.rejected += 1;
                continue;
            }
            let fac11 = err.powf(expo);
            if err <= 1.0 {
                if !fsal_in_error {
                    self.eval(model, data, control, t + pair.c[s_end] * h, s_end)?;
                }
                let fac = fac11 / self.err_prev.powf(tol.beta);
                let fac = (fac / SAFE).clamp(1.0 / pair.fac_max, 1.0 / pair.fac_min);
                let mut h_new = h / fac;
                if self.rejected_last {
                    h_new = h_new.min(h);
                }
                self.err_prev = err.max(1e-4);
                self.rejected_last = false;
                // A shortened last step must not shrink the step size kept for later calls.
                self.h = if last { h_new.max(self.h) } else { h_new };
                if last {
                    (self.t, self.t_comp) = (t_end, 0.0);
                } else {
                    // Kahan: t + h with the rounding of the earlier sums carried along.
                    let y = h - self.t_comp;
                    let sum = t + y;
                    self.t_comp = (sum - t) - y;
                    self.t = sum;
                }
                if self.options.stabilization == Stabilization::CoordinatePartitioning {
                    self.x = self.x_full;
                    self.xdot = self.v_full;
                } else {
                    self.x = self.xs;
                    self.xdot = self.vs;
                }
                for i in 0..N {
                    self.kx[i][0] = self.kx[i][s_end];
                    self.kv[i][0] = self.kv[i][s_end];
                }
                return Ok(h);
            }
            self.h = h / (fac11 / SAFE).min(1.0 / pair.fac_min);
            self.rejected_last = true;
            self.stats.rejected += 1;
        }
    }

    /// The scaled error of the trial step `h` (accepted when `<= 1`): the root mean square of
    /// `e_i / (atol + rtol max(|y_i|, |y_new_i|))` for DOPRI5; DOP853's combination of its
    /// fifth- and third-order estimates in the same norm.
    fn error(&self, pair: &Pair, h: f64, tol: &Tolerances) -> f64 {
        let n = (2 * self.n_active.max(1)) as f64;
        let (mut sum, mut sum3) = (0.0, 0.0);
        for &i in &self.active[..self.n_active] {
            let (mut ex, mut ev) = (0.0, 0.0);
            for (j, &e) in pair.e.iter().enumerate() {
                ex += e * self.kx[i][j];
                ev += e * self.kv[i][j];
            }
            let skx = tol.atol + tol.rtol * self.x[i].abs().max(self.xs[i].abs());
            let skv = tol.atol + tol.rtol * self.xdot[i].abs().max(self.vs[i].abs());
            if pair.e3.is_empty() {
                sum += (h * ex / skx).powi(2) + (h * ev / skv).powi(2);
                continue;
            }
            sum += (ex / skx).powi(2) + (ev / skv).powi(2);
            let (mut ex3, mut ev3) = (0.0, 0.0);
            for (j, &e) in pair.e3.iter().enumerate() {
                ex3 += e * self.kx[i][j];
                ev3 += e * self.kv[i][j];
            }
            sum3 += (ex3 / skx).powi(2) + (ev3 / skv).powi(2);
        }
        if pair.e3.is_empty() {
            return (sum / n).sqrt();
        }
        let denominator = sum + 0.01 * sum3;
        if denominator > 0.0 {
            h.abs() * sum / (n * denominator).sqrt()
        } else {
            // Both estimates vanish (or a NaN, which the caller rejects).
            if denominator.is_nan() { f64::NAN } else { 0.0 }
        }
    }

    /// Hairer's `HINIT`: a first step from the size of `y`, `y'` and an estimate of `y''`
    /// (one extra evaluation, in stage slot 1). Expects the derivative at `y` in stage 0.
    fn initial_step<K, C>(
        &mut self,
        pair: &Pair,
        model: &Model<K, N, M>,
        data: &mut Data<N, M>,
        control: &mut C,
        tol: Tolerances,
    ) -> Result<f64, IntegrateError>
    where
        K: Simulate<N, M>,
        C: FnMut(f64, &[f64; N], &[f64; N], &mut [f64]) -> Result<(), SolverError> + ?Sized,
    {
        let (rtol, atol, h_max) = (tol.rtol, tol.atol, tol.h_max);
        let (mut dnf, mut dny) = (0.0, 0.0);
        for &i in &self.active[..self.n_active] {
            let skx = atol + rtol * self.x[i].abs();
            let skv = atol + rtol * self.xdot[i].abs();
            dnf += (self.kx[i][0] / skx).powi(2) + (self.kv[i][0] / skv).powi(2);
            dny += (self.x[i] / skx).powi(2) + (self.xdot[i] / skv).powi(2);
        }
        let mut h = if dnf <= 1e-10 || dny <= 1e-10 {
            1e-6
        } else {
            (dny / dnf).sqrt() * 0.01
        };
        h = h.min(h_max);
        self.stage_state(h, &[1.0]);
        self.eval(model, data, control, self.t + h, 1)?;
        let mut der2 = 0.0;
        for &i in &self.active[..self.n_active] {
            let skx = atol + rtol * self.x[i].abs();
            let skv = atol + rtol * self.xdot[i].abs();
            der2 += ((self.kx[i][1] - self.kx[i][0]) / skx).powi(2)
                + ((self.kv[i][1] - self.kv[i][0]) / skv).powi(2);
        }
        let der2 = der2.sqrt() / h;
        let der12 = der2.max(dnf.sqrt());
        let h1 = if der12 <= 1e-15 {
            (h * 1e-3).max(1e-6)
        } else {
            (0.01 / der12).powf(pair.expo)
        };
        let h0 = (100.0 * h).min(h1).min(h_max);
        if h0.is_finite() && h0 > 0.0 {
            Ok(h0)
        } else {
            Err(IntegrateError::StepSizeTooSmall { t: self.t, h: h0 })
        }
    }
}

fn max_diff<const N: usize>(a: &[f64; N], b: &[f64; N]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
}
