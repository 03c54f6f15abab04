//! Continuation: [`forward_kinematics_path`] and [`inverse_kinematics_path`] walk from the start
//! to the target along the straight segment of the actuated values (or outputs), in steps that
//! each converge from a predictor within a few Newton iterations and keep the signs that matter
//! to the problem ([`Parts`]: `J_p` for forward kinematics, the blocks for inverse kinematics;
//! see [`certify`](super::certify) for the signatures). What they return is the configuration
//! the mechanism reaches by moving along that segment from the start — the start's mode — or a
//! typed error saying where the path meets a singularity ([`SolverError::ModeChange`] with the
//! part whose sign changed, or [`SolverError::PathStalled`]).

use super::certify::{ModeSignature, Parts, certify_position, mode_signature};
use super::forward_kinematics::forward_kinematics;
use super::input::{check_finite, max_abs};
use super::inverse_kinematics::inverse_kinematics;
use crate::data::Data;
use crate::error::SolverError;
use crate::model::Model;
use crate::tasks::{ForwardKinematics, InverseKinematics};

/// Settings of [`forward_kinematics_path`] and [`inverse_kinematics_path`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathOptions {
    /// The first step, as a fraction of the way (default `0.1`).
    pub first_step: f64,
    /// The longest step, as a fraction of the way (default `0.1`: at least ten steps, so that
    /// no single Newton solve can jump between modes across the whole way).
    pub max_step: f64,
    /// The shortest step before the path is declared stalled (default `1e-6`).
    pub min_step: f64,
    /// A step is accepted when Newton from the predictor converges within this many iterations
    /// (default `6`): quadratic convergence from a close predictor, not a jump.
    pub max_iterations: usize,
    /// Accept a sign change of the signature on the way (a path through a singularity of a
    /// block: the mechanism changes mode there). Default `false`: such a change is
    /// [`SolverError::ModeChange`].
    pub allow_mode_change: bool,
    /// Most steps, accepted plus rejected (default `10_000`).
    pub max_steps: usize,
    /// A step is accepted only when no coordinate moved more than this (m or rad; default
    /// `0.2`): near a singularity the passive coordinates race (a wrist's two angles swing by
    /// pi as its middle angle passes zero), and a long step there can land on another branch
    /// whose signs are the same (two factors of a determinant flipped at once). Shorter steps
    /// follow the race, and meet the singularity as a sign change or a stall.
    pub max_move: f64,
    /// A step is accepted only when Newton's correction of the predictor moved no coordinate
    /// more than this (m or rad; default `0.05`): the predictor is good to second order in the
    /// step, so a large correction means the step left the path.
    pub max_correction: f64,
}

impl Default for PathOptions {
    fn default() -> Self {
        Self {
            first_step: 0.1,
            max_step: 0.1,
            min_step: 1e-6,
            max_iterations: 6,
            allow_mode_change: false,
            max_steps: 10_000,
            max_move: 0.2,
            max_correction: 0.05,
        }
    }
}

/// What a successful continuation reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathReport<const M: usize> {
    /// Steps accepted.
    pub steps: usize,
    /// Steps rejected (and retried shorter).
    pub rejected: usize,
    /// Newton iterations, summed over every step tried.
    pub iterations: usize,
    /// `max |f|` at the returned configuration.
    pub residual: f64,
    /// The worst condition number reported by the accepted steps.
    pub cond: f64,
    /// The largest unsolved loop component at the returned configuration ([`certify_position`]).
    pub closure_check: f64,
    /// The signature at the start and at the returned configuration (equal in the parts the
    /// path keeps unless `allow_mode_change`).
    pub start_signature: ModeSignature<M>,
    /// See `start_signature`.
    pub signature: ModeSignature<M>,
    /// Sign changes accepted on the way (`allow_mode_change`).
    pub mode_changes: usize,
}

/// Which solve a path runs at each step.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Fk,
    Ik,
}

/// Forward kinematics by continuation: from the start `data.x` (polished by Newton at its own
/// actuated values first, so it must be an assembly or close to one) to the actuated values
/// `q`, along `q(t) = q_0 + t (q - q_0)`, `t` from 0 to 1. Each step predicts linearly from the
/// last two points, solves by [`forward_kinematics()`] and is accepted when Newton converged in
/// at most `PathOptions::max_iterations` iterations, moved no coordinate more than
/// `max_move` (nor corrected the predictor by more than `max_correction`), and the sign of
/// `det J_p` is kept
/// ([`Parts::Jp`]: the blocks' signs may change on the way, see there); otherwise the step is
/// halved. Writes `data.x` on success only.
///
/// Errors: those of `forward_kinematics` at the start; [`SolverError::ModeChange`] when the
/// sign of `det J_p` changes on the way at the shortest step (the path crosses a singularity of that part: another
/// mode lies beyond; allow it with `PathOptions::allow_mode_change`);
/// [`SolverError::PathStalled`] when steps of `min_step` still fail (a singularity of `J_p`, or
/// the limit of the reach, on the way); [`SolverError::SpuriousRoot`] from the certificate.
pub fn forward_kinematics_path<K, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q: &[f64],
    options: &PathOptions,
) -> Result<PathReport<M>, SolverError>
where
    K: InverseKinematics<N, M> + ForwardKinematics<N, M>,
{
    model.structure().require_actuated("forward kinematics")?;
    let idx = model.structure().actuated;
    path(model, data, q, idx, Kind::Fk, options)
}

/// Inverse kinematics by continuation, as [`forward_kinematics_path`] over the outputs: from
/// the start `data.x` to the outputs `outputs`, each step by [`inverse_kinematics()`], keeping
/// the signs of the inverse-kinematics blocks (a leg's working mode). Writes `data.x` on
/// success only.
pub fn inverse_kinematics_path<K, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs: &[f64],
    options: &PathOptions,
) -> Result<PathReport<M>, SolverError>
where
    K: InverseKinematics<N, M> + ForwardKinematics<N, M>,
{
    model.structure().require_outputs("inverse kinematics")?;
    let idx = model.structure().outputs;
    path(model, data, outputs, idx, Kind::Ik, options)
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0, |m: f64, (x, y)| m.max((x - y).abs()))
}

fn path<K, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    target: &[f64],
    idx: &[usize],
    kind: Kind,
    o: &PathOptions,
) -> Result<PathReport<M>, SolverError>
where
    K: InverseKinematics<N, M> + ForwardKinematics<N, M>,
{
    let what = match kind {
        Kind::Fk => "q",
        Kind::Ik => "outputs",
    };
    super::input::check_input(what, target, idx.len())?;
    check_finite("data.x (start)", &data.x)?;
    let ok = |v: f64| v.is_finite() && v > 0.0 && v <= 1.0;
    let positive = |v: f64| v > 0.0 && !v.is_nan();
    let valid = ok(o.first_step)
        && ok(o.max_step)
        && ok(o.min_step)
        && o.max_iterations > 0
        && positive(o.max_move)
        && positive(o.max_correction);
    if !valid {
        return Err(SolverError::NonFinite {
            what: "PathOptions (first_step, max_step, min_step in (0, 1], max_iterations, \
                   max_move, max_correction > 0)",
        });
    }
    let saved = data.x;
    let solve = |data: &mut Data<N, M>, v: &[f64]| match kind {
        Kind::Fk => forward_kinematics(model, data, v),
        Kind::Ik => inverse_kinematics(model, data, v),
    };
    let parts = match kind {
        Kind::Fk => Parts::Jp,
        Kind::Ik => Parts::Blocks,
    };
    let from: [f64; M] = {
        let mut a = [0.0; M];
        for (k, &j) in idx.iter().enumerate().take(M) {
            a[k] = data.x[j];
        }
        a
    };
    let n_idx = idx.len().min(M);
    let at = |t: f64, out: &mut [f64; M]| {
        for k in 0..n_idx {
            out[k] = from[k] + t * (target[k] - from[k]);
        }
    };
    // The start, polished at its own values.
    let mut v = [0.0; M];
    at(0.0, &mut v);
    let r0 = match solve(data, &v[..n_idx]) {
        Ok(r) => r,
        Err(e) => {
            data.x = saved;
            return Err(e);
        }
    };
    let start_signature = mode_signature(model, &data.x);
    let mut rep = PathReport {
        steps: 0,
        rejected: 0,
        iterations: r0.iterations,
        residual: r0.residual,
        cond: r0.cond,
        closure_check: 0.0,
        start_signature,
        signature: start_signature,
        mode_changes: 0,
    };
    let (mut t, mut h) = (0.0_f64, o.first_step.min(o.max_step));
    let mut x = data.x;
    let mut x_prev: Option<(f64, [f64; N])> = None;
    let mut tries = 0;
    while t < 1.0 {
        tries += 1;
        if tries > o.max_steps {
            data.x = saved;
            return Err(SolverError::PathStalled {
                t,
                residual: max_abs(&data.f),
            });
        }
        let t1 = (t + h).min(1.0);
        // Predictor: the secant through the last two points, else the last point.
        let mut start = x;
        if let Some((tp, xp)) = x_prev {
            let s = (t1 - t) / (t - tp);
            for j in 0..N {
                start[j] = x[j] + s * (x[j] - xp[j]);
            }
        }
        data.x = start;
        at(t1, &mut v);
        let step = solve(data, &v[..n_idx]);
        let dist = |a: &[f64; N], b: &[f64; N]| max_abs_diff(a, b);
        let short = dist(&data.x, &x) <= o.max_move && dist(&data.x, &start) <= o.max_correction;
        let verdict = match step {
            Ok(r) if r.iterations <= o.max_iterations && short => {
                rep.iterations += r.iterations;
                let sig = mode_signature(model, &data.x);
                match rep.signature.first_difference(&sig, parts) {
                    None => Ok((r, sig)),
                    Some(d) => Err(Some(d)),
                }
            }
            Ok(r) => {
                rep.iterations += r.iterations;
                Err(None)
            }
            // An overflow is the input's, not the step's.
            Err(e @ SolverError::NonFinite { .. }) => {
                data.x = saved;
                return Err(e);
            }
            // A spurious root is a step too long (the predictor near a mirror root).
            Err(_) => Err(None),
        };
        match verdict {
            Ok((r, sig)) => {
                x_prev = Some((t, x));
                x = data.x;
                t = t1;
                rep.steps += 1;
                rep.residual = r.residual;
                rep.cond = rep.cond.max(r.cond);
                rep.signature = sig;
                h = (2.0 * h).min(o.max_step);
            }
            Err(change) => {
                rep.rejected += 1;
                if h > o.min_step {
                    h = (h / 2.0).max(o.min_step);
                    continue;
                }
                // The shortest step still fails.
                match (change, step) {
                    (Some(_), Ok(r)) if o.allow_mode_change => {
                        let sig = mode_signature(model, &data.x);
                        x_prev = Some((t, x));
                        x = data.x;
                        t = t1;
                        rep.steps += 1;
                        rep.mode_changes += 1;
                        rep.residual = r.residual;
                        rep.cond = rep.cond.max(r.cond);
                        rep.signature = sig;
                        h = o.first_step.min(o.max_step);
                    }
                    (Some((part, from, to)), _) => {
                        data.x = saved;
                        return Err(SolverError::ModeChange {
                            part,
                            start: from,
                            found: to,
                            t,
                        });
                    }
                    (None, Err(SolverError::SpuriousRoot { check, residual })) => {
                        data.x = saved;
                        return Err(SolverError::SpuriousRoot { check, residual });
                    }
                    (None, _) => {
                        data.x = saved;
                        return Err(SolverError::PathStalled {
                            t,
                            residual: max_abs(&data.f),
                        });
                    }
                }
            }
        }
    }
    data.x = x;
    rep.closure_check = certify_position(model, &data.x)?;
    Ok(rep)
}
