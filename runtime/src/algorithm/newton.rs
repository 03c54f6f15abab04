//! Block Newton with backtracking: the position solvers' iteration (inverse kinematics on its
//! blocks, forward kinematics on `J_p`), from `data.ws.x`.

use nalgebra::SMatrix;

use super::blockwise::Blocks;
use super::generated;
use super::input::{all_finite, check_finite, max_abs};
use super::reduced;
use super::report::SolveReport;
use crate::data::{BlockFactors, BlockState, Data, NewtonScratch, Workspace};
use crate::error::SolverError;
use crate::factor::{
    CondMode, Conditioning, G_SOURCE, Slot, check_cond, condition, factor_block, lu_error,
    reported_cond, slot_error, slot_ref, solve_block,
};
use crate::kernels::IkBlock;
use crate::linalg;
use crate::model::Model;
use crate::plan::invert_block;
use crate::tasks::Constraints;

/// Cap on `SolverOptions::max_step_halvings`: a step of `2^-60` is below rounding anyway.
const MAX_HALVINGS: u32 = 60;

/// Forward kinematics' chord steps (`J_p` kept from the last full step) continue while each
/// reduces `‖f‖₂` at least this much; a step that did not gets a full Newton step next.
const CHORD_RATE: f64 = 0.01;

/// The fused kernel of a Newton solve: `constraints` and a column subset of `G` at once
/// (`Kernels::constraints_jacobian_ik` or `Kernels::constraints_jacobian_p`).
pub(crate) type NewtonKernel<K, const N: usize, const M: usize> =
    fn(&K, &[f64; N], &mut [f64; M], &mut [[f64; M]; N]);

/// Newton's method on independent blocks, from the iterate `data.ws.x` (set by the caller,
/// finite). Each evaluation calls the fused `kernel` (`constraints` and the Jacobian columns)
/// once for all blocks; each unconverged block then either tests its trial step (backtracking)
/// or takes a Newton step. Converged blocks stop updating; the step that passes the convergence
/// test is applied, and one more `constraints` call measures the returned residual. On success
/// `data.ws.x` is the solution, `data.f` is `f` there, and `data.g` is the Jacobian one (tiny)
/// step before it (forward kinematics' chord steps: at the last full step).
///
/// Forward kinematics by the generated elimination takes **chord steps** where the generator
/// found them cheaper (`FR_CHORD` of the robot's crate): a full step keeps the elimination's
/// factors (`Kernels::forward_rates_keep`), and the steps after it evaluate `constraints` alone
/// and solve with those factors (`Kernels::forward_rates_chord`) while each reduces `‖f‖₂` by
/// `CHORD_RATE`; a step that did not, or the step that can converge when the options ask for
/// the exact condition number, is a full step again. A chord step reduces the error by its
/// rate only, so it converges where that rate times the step is below rounding, which gives
/// the point full steps give to a few ulps (`tests/generated_kinematics.rs`).
///
/// When every block has the same order `B <= linalg::SMALL` (3 for a Stewart platform, 2 for a
/// five-bar), the loop is compiled for that order: the blocks are gathered, inverted and
/// applied in registers, without a loop over a run-time length.
pub(crate) fn newton<K: Constraints<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: Blocks<'_>,
    kernel: NewtonKernel<K, N, M>,
    what: &'static str,
) -> Result<SolveReport, SolverError> {
    match blocks {
        Blocks::Ik(ik) => {
            by_ik_order!(K, ik, B => match newton_fixed::<K, N, M, B>(model, data, ik, kernel, what) {
            Some(r) => r,
            None => newton_impl::<K, N, M, B>(model, data, blocks, kernel, what),
        }, _ => newton_impl::<K, N, M, 0>(model, data, blocks, kernel, what))
        }
        // Forward kinematics: one system of all M rows.
        Blocks::Single { rows, .. } if rows.len() == M => by_order!(M, B =>
            newton_impl::<K, N, M, B>(model, data, blocks, kernel, what),
            _ => newton_impl::<K, N, M, 0>(model, data, blocks, kernel, what)),
        Blocks::Single { .. } => newton_impl::<K, N, M, 0>(model, data, blocks, kernel, what),
    }
}

/// [`newton`] on inverse-kinematics blocks all of order `B` (`None`: they are not; nothing
/// done), with the blocks' index lists as arrays: the same iteration as [`newton_impl`], every
/// per-block loop of compile-time length.
fn newton_fixed<K: Constraints<N, M>, const N: usize, const M: usize, const B: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    ik: &[IkBlock],
    kernel: NewtonKernel<K, N, M>,
    what: &'static str,
) -> Option<Result<SolveReport, SolverError>> {
    let nb = ik.len();
    if nb > M {
        return None;
    }
    let mut idx = [([0_usize; B], [0_usize; B]); M];
    for (slot, blk) in idx.iter_mut().zip(ik) {
        *slot = (blk.rows.try_into().ok()?, blk.cols.try_into().ok()?);
    }
    let idx = &idx[..nb];
    let o = model.options;
    let kern = model.kernels();
    let Data { f, g, ws, .. } = data;
    let Workspace {
        x,
        dx,
        newton: NewtonScratch { x_base, states, .. },
        ..
    } = ws;
    let states = &mut states[..nb];
    states.fill(BlockState::default());
    let mut evaluations = 0;
    let fail = |e| Some(Err(e));
    loop {
        kernel(kern, x, f, &mut g.data.0);
        evaluations += 1;
        let mut done = true;
        for (b, (st, (rows, cols))) in states.iter_mut().zip(idx).enumerate() {
            if st.converged {
                continue;
            }
            let fb: [f64; B] = core::array::from_fn(|i| f[rows[i]]);
            let (mut rmax, mut r2) = (0.0_f64, 0.0_f64);
            for &v in &fb {
                rmax = rmax.max(v.abs());
                r2 += v * v;
            }
            if r2.is_nan() || rmax == f64::INFINITY {
                return fail(SolverError::NonFinite {
                    what: "f (constraint kernel output)",
                });
            }
            let rnorm = r2.sqrt();
            if st.trial {
                let accept = rmax <= o.tol_f
                    || rnorm <= (1.0 - 1e-4 * st.alpha) * st.norm_base
                    || st.halvings >= o.max_step_halvings.min(MAX_HALVINGS);
                if !accept {
                    st.alpha *= 0.5;
                    st.halvings += 1;
                    for &j in cols {
                        x[j] = x_base[j] + st.alpha * dx[j];
                    }
                    done = false;
                    continue;
                }
                st.trial = false;
            }

            // Newton step at x: G_b dx = -f_b.
            let (inv, anorm, inv_norm) = match invert_block::<N, M, B>(g, rows, cols) {
                Ok(r) => r,
                Err(e) => return fail(lu_error(e, what, Some(b), B, G_SOURCE)),
            };
            let cond = match check_cond(condition(anorm, inv_norm), o.cond_max, what, Some(b)) {
                Ok(c) => c,
                Err(e) => return fail(e),
            };
            let step = linalg::mul_fixed(&inv, &fb);
            let (mut dmax, mut xmax, mut finite) = (0.0_f64, 0.0_f64, true);
            for (&d, &j) in step.iter().zip(cols) {
                dmax = dmax.max(d.abs());
                xmax = xmax.max(x[j].abs());
                finite &= d.is_finite();
                dx[j] = -d;
            }
            if !finite {
                return fail(SolverError::NonFinite {
                    what: "Newton step",
                });
            }
            if rmax <= o.tol_f && dmax <= o.tol_x * (1.0 + xmax) {
                // Converged; the last, tiny step is still applied.
                st.converged = true;
                st.cond = cond;
                for &j in cols {
                    x[j] += dx[j];
                }
                continue;
            }
            if st.steps >= o.max_iterations {
                return fail(SolverError::NotConverged {
                    iterations: st.steps,
                    residual: max_abs(f),
                });
            }
            st.steps += 1;
            st.trial = true;
            st.alpha = 1.0;
            st.halvings = 0;
            st.norm_base = rnorm;
            for &j in cols {
                x_base[j] = x[j];
                x[j] += dx[j];
            }
            done = false;
        }
        if done {
            break;
        }
    }
    // The residual at the returned point, after the final steps.
    kern.constraints(x, f);
    if !all_finite(f) {
        return fail(SolverError::NonFinite {
            what: "f (constraint kernel output)",
        });
    }
    let mut rep = SolveReport {
        iterations: 0,
        evaluations,
        residual: 0.0,
        cond: 0.0,
    };
    for (st, (rows, _)) in states.iter().zip(idx) {
        for &i in rows {
            rep.residual = rep.residual.max(f[i].abs());
        }
        rep.iterations = rep.iterations.max(st.steps);
        rep.cond = rep.cond.max(st.cond);
    }
    Some(Ok(rep))
}

/// [`newton`] for blocks of order `B` (`B = 0`: any order, factored in the workspace).
fn newton_impl<K: Constraints<N, M>, const N: usize, const M: usize, const B: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: Blocks<'_>,
    kernel: NewtonKernel<K, N, M>,
    what: &'static str,
) -> Result<SolveReport, SolverError> {
    let o = model.options;
    let kern = model.kernels();
    let Data { f, g, ws, .. } = data;
    let Workspace {
        x,
        dx,
        rhs,
        newton:
            NewtonScratch {
                x_base,
                states,
                chord: store,
            },
        factors: BlockFactors { lu, piv, work },
        fk,
        ..
    } = ws;
    let nb = blocks.len().min(M);
    let states = &mut states[..nb];
    states.fill(BlockState::default());
    let mut evaluations = 0;
    // Forward kinematics by the generated elimination: after a full step that kept its factors
    // (their condition number here), the next steps are chord steps, `J_p` as it was there, the
    // evaluations `constraints` alone, while they contract by `CHORD_RATE`.
    let chord_here = B == 0 && matches!(blocks, Blocks::Single { .. });
    let mut kept: Option<f64> = None;
    loop {
        if kept.is_some() {
            kern.constraints(x, f);
        } else {
            kernel(kern, x, f, &mut g.data.0);
        }
        evaluations += 1;
        let mut done = true;
        let mut slot = Slot::default();
        for (b, st) in states.iter_mut().enumerate() {
            let (rows, cols, block) = blocks.get(b);
            slot = slot.next(rows.len());
            if st.converged {
                continue;
            }
            let (mut rmax, mut rnorm) = rows_residual(f, rows)?;
            if st.trial {
                let accept = rmax <= o.tol_f
                    || rnorm <= (1.0 - 1e-4 * st.alpha) * st.norm_base
                    || st.halvings >= o.max_step_halvings.min(MAX_HALVINGS);
                if !accept {
                    st.alpha *= 0.5;
                    st.halvings += 1;
                    for &j in cols {
                        x[j] = x_base[j] + st.alpha * dx[j];
                    }
                    done = false;
                    continue;
                }
                st.trial = false;
            }

            // Newton step at x: G_b dx = -f_b.
            let k = slot.k;
            let step = &mut rhs[..k];
            // A chord step where the last one contracted and the options do not ask for the
            // exact condition number at the step that can converge.
            let (mut chord_cond, mut chord_rate) = (None, 0.0);
            if let Some(c) = kept.take() {
                let exact_now = rmax <= o.tol_f && o.exact_cond;
                if rnorm <= CHORD_RATE * st.norm_base && !exact_now && {
                    let minus_f: [f64; M] = core::array::from_fn(|i| -f[i]);
                    kern.forward_rates_chord(store.as_flattened(), &minus_f, dx)
                        .is_some()
                } {
                    for (s, &j) in step.iter_mut().zip(cols) {
                        *s = dx[j];
                    }
                    chord_cond = Some(c);
                    chord_rate = rnorm / st.norm_base;
                } else {
                    // A full step at x: its Jacobian (and `f` with it).
                    kernel(kern, x, f, &mut g.data.0);
                    evaluations += 1;
                    (rmax, rnorm) = rows_residual(f, rows)?;
                }
            }
            // Forward kinematics: J_p by elimination onto the outputs when it certifies itself.
            let mut structured = false;
            let cond = if let Some(cond) = chord_cond {
                kept = Some(cond);
                Conditioning {
                    cond,
                    anorm: 0.0,
                    reportable: true,
                }
            } else if B > 0 {
                newton_step_fixed::<N, M, B>(g, f, rows, cols, step, o.cond_max, what, block)?
            } else if let (Blocks::Ik(_), Some(b)) = (blocks, block)
                && let Some(cond) =
                    generated::ik_newton_step(kern, b, cols, &g.data.0, f, dx, step, o.cond_max)
            {
                // The block solve the generator emitted; its condition number is reportable.
                Conditioning {
                    cond,
                    anorm: 0.0,
                    reportable: true,
                }
            } else if let Blocks::Single { .. } = blocks
                && let Some((cond, keeps)) = generated::fk_newton_step(
                    kern,
                    cols,
                    &g.data.0,
                    f,
                    dx,
                    step,
                    o.cond_max,
                    rmax <= o.tol_f && o.exact_cond,
                    store.as_flattened_mut(),
                )
            {
                if keeps && chord_here {
                    kept = Some(cond);
                }
                // The elimination the generator emitted: its rigorous upper bound decides
                // `Singular` while the residual is above `tol_f`; the step that can converge
                // reports the bound, or the exact condition number if the options ask for it
                // (`SolverOptions::exact_cond`). Where the bound does not certify, the
                // runtime's own elimination and then the LU decide on the exact value or the
                // estimate.
                Conditioning {
                    cond,
                    anorm: 0.0,
                    reportable: rmax <= o.tol_f,
                }
            } else if let Blocks::Single { .. } = blocks
                && let Some(bound) = reduced::fk_factor(model, g, fk, o.cond_max)
            {
                structured = true;
                let minus_f: [f64; M] = core::array::from_fn(|i| -f[i]);
                let mut d = [0.0; N];
                reduced::fk_solve(model, fk, &minus_f, &mut d);
                for (sv, &j) in step.iter_mut().zip(cols) {
                    *sv = d[j];
                }
                Conditioning {
                    cond: bound,
                    anorm: 0.0,
                    reportable: false,
                }
            } else {
                let c = factor_block(
                    g,
                    rows,
                    cols,
                    slot,
                    lu,
                    piv,
                    work,
                    o.cond_max,
                    CondMode::Decide,
                    what,
                    block,
                )?;
                for (s, &i) in step.iter_mut().zip(rows) {
                    *s = -f[i];
                }
                solve_block(lu, piv, slot, step, false, what, block)?;
                c
            };
            let (mut dmax, mut xmax, mut finite) = (0.0_f64, 0.0_f64, true);
            for (&d, &j) in step.iter().zip(cols) {
                dmax = dmax.max(d.abs());
                xmax = xmax.max(x[j].abs());
                finite &= d.is_finite();
                dx[j] = d;
            }
            if !finite {
                return Err(SolverError::NonFinite {
                    what: "Newton step",
                });
            }
            // A chord step reduces the error only by its rate (Newton's by its square): it
            // converges where what it leaves is below rounding, as Newton's last step does.
            let chord_done =
                chord_cond.is_none() || chord_rate * dmax <= f64::EPSILON * (1.0 + xmax);
            if rmax <= o.tol_f && dmax <= o.tol_x * (1.0 + xmax) && chord_done {
                // Converged; the last, tiny step is still applied: it costs nothing and
                // Newton's quadratic convergence makes the solution far more accurate.
                st.converged = true;
                st.cond = if structured {
                    check_cond(reduced::fk_cond::<N, M>(fk), o.cond_max, what, block)?
                } else if B > 0 {
                    cond.cond
                } else {
                    let (a, p) = slot_ref(lu, piv, slot)?;
                    reported_cond(
                        cond,
                        a,
                        k,
                        p,
                        work.as_flattened_mut(),
                        o.cond_max,
                        what,
                        block,
                    )?
                };
                for &j in cols {
                    x[j] += dx[j];
                }
                continue;
            }
            if st.steps >= o.max_iterations {
                return Err(SolverError::NotConverged {
                    iterations: st.steps,
                    residual: max_abs(f),
                });
            }
            st.steps += 1;
            st.trial = true;
            st.alpha = 1.0;
            st.halvings = 0;
            st.norm_base = rnorm;
            for &j in cols {
                x_base[j] = x[j];
                x[j] += dx[j];
            }
            done = false;
        }
        if done {
            break;
        }
    }
    // The residual at the returned point, after the final steps.
    kern.constraints(x, f);
    check_finite("f (constraint kernel output)", f)?;
    let mut rep = SolveReport {
        iterations: 0,
        evaluations,
        residual: 0.0,
        cond: 0.0,
    };
    for (b, st) in states.iter().enumerate() {
        let (rows, _, _) = blocks.get(b);
        for &i in rows {
            rep.residual = rep.residual.max(f[i].abs());
        }
        rep.iterations = rep.iterations.max(st.steps);
        rep.cond = rep.cond.max(st.cond);
    }
    Ok(rep)
}

/// `(max |f_i|, ‖f‖₂)` over a block's `rows`; `NonFinite` for a NaN or an infinity there.
fn rows_residual<const M: usize>(f: &[f64; M], rows: &[usize]) -> Result<(f64, f64), SolverError> {
    let (mut rmax, mut r2) = (0.0_f64, 0.0_f64);
    for &i in rows {
        let v = f[i];
        rmax = rmax.max(v.abs());
        r2 += v * v;
    }
    if r2.is_nan() || rmax == f64::INFINITY {
        return Err(SolverError::NonFinite {
            what: "f (constraint kernel output)",
        });
    }
    Ok((rmax, r2.sqrt()))
}

/// The Newton step `step = -G_b⁻¹ f_b` of a block of order `B <= linalg::SMALL`, with the exact
/// condition number of `G_b` checked against `cond_max`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn newton_step_fixed<const N: usize, const M: usize, const B: usize>(
    g: &SMatrix<f64, M, N>,
    f: &[f64; M],
    rows: &[usize],
    cols: &[usize],
    step: &mut [f64],
    cond_max: f64,
    what: &'static str,
    block: Option<usize>,
) -> Result<Conditioning, SolverError> {
    let (Ok(rows), Ok(cols), Ok(step)) = (
        <&[usize; B]>::try_from(rows),
        <&[usize; B]>::try_from(cols),
        <&mut [f64; B]>::try_from(step),
    ) else {
        return Err(slot_error(Slot {
            k: B,
            off: 0,
            poff: 0,
        }));
    };
    let (inv, anorm, inv_norm) = invert_block::<N, M, B>(g, rows, cols)
        .map_err(|e| lu_error(e, what, block, B, G_SOURCE))?;
    let cond = check_cond(condition(anorm, inv_norm), cond_max, what, block)?;
    let minus_f: [f64; B] = core::array::from_fn(|i| -f[rows[i]]);
    *step = linalg::mul_fixed(&inv, &minus_f);
    Ok(Conditioning {
        cond,
        anorm,
        reportable: true,
    })
}
