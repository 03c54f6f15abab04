//! Warnings: a model that compiles but probably does not say what was meant.
//!
//! - An angle-valued parameter (a summand of a rotation step's angle or of the argument of
//!   `sin`, `cos`, `tan`) whose value exceeds 2*pi in magnitude and whose unit is neither `deg`
//!   nor `rad`: `alpha = 120` is taken as 120 rad, and was most likely meant in degrees.

use std::f64::consts::TAU;

use super::*;

/// The parameters that are summands of `e` (through `+`, `-` and unary minus).
fn summands(e: &Expr, out: &mut Vec<usize>) {
    match e {
        Expr::Param(j) => out.push(*j),
        Expr::Add(a, b) | Expr::Sub(a, b) => {
            summands(a, out);
            summands(b, out);
        }
        Expr::Neg(a) => summands(a, out),
        _ => {}
    }
}

/// Angle-valued parameters of `e`'s trigonometric calls.
fn trig_arguments(e: &Expr, out: &mut Vec<usize>) {
    match e {
        Expr::Call(f, args) => {
            for a in args {
                if matches!(f, Func::Sin | Func::Cos | Func::Tan) {
                    summands(a, out);
                }
                trig_arguments(a, out);
            }
        }
        Expr::Neg(a) => trig_arguments(a, out),
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) | Expr::Pow(a, b) => {
            trig_arguments(a, out);
            trig_arguments(b, out);
        }
        Expr::Num { .. } | Expr::Pi | Expr::Param(_) | Expr::Coord(_) => {}
    }
}

fn step_angles(steps: &[Step], out: &mut Vec<usize>) {
    for s in steps {
        match s {
            Step::Rot(_, e) => {
                summands(e, out);
                trig_arguments(e, out);
            }
            Step::Trans(_, e) => trig_arguments(e, out),
            Step::Rotation(m) => m.iter().flatten().for_each(|e| trig_arguments(e, out)),
            Step::Quat(q) => q.iter().for_each(|e| trig_arguments(e, out)),
        }
    }
}

impl Parser<'_> {
    /// Collects the model's warnings into `self.warnings`.
    pub(super) fn collect_warnings(&mut self, model: &Model) {
        // (parameter, where it is used as an angle), first use only.
        let mut uses: Vec<(usize, String)> = Vec::new();
        let mut note = |found: Vec<usize>, place: String| {
            for j in found {
                if !uses.iter().any(|(k, _)| *k == j) {
                    uses.push((j, place.clone()));
                }
            }
        };
        for p in &model.parameters {
            let mut found = Vec::new();
            trig_arguments(&p.expr, &mut found);
            note(found, format!("the value of parameter `{}`", p.name));
        }
        for b in &model.bodies {
            let mut found = Vec::new();
            step_angles(&b.steps, &mut found);
            if let Some(m) = &b.inertia {
                for e in std::iter::once(&m.mass).chain(&m.com).chain(&m.inertia) {
                    trig_arguments(e, &mut found);
                }
            }
            note(found, format!("the transforms of body `{}`", b.name));
        }
        for l in &model.loops {
            let mut found = Vec::new();
            step_angles(&l.a.steps, &mut found);
            step_angles(&l.b.steps, &mut found);
            note(found, format!("loop `{}`", l.name));
        }
        uses.sort_by_key(|(j, _)| *j);
        for (j, place) in uses {
            let p = &model.parameters[j];
            if p.value.abs() <= TAU || p.unit == "deg" || p.unit == "rad" || !p.value.is_finite() {
                continue;
            }
            let shown = fmt_num(p.value);
            let d = Diagnostic::new(
                p.pos,
                p.name.chars().count(),
                format!(
                    "parameter `{}` = {shown} is an angle (in {place}) and is taken as {shown} rad, more than 2*pi",
                    p.name
                ),
                "an angle above 2*pi in radians",
            )
            .with_help(format!(
                "for degrees write `{} = {{ value = {shown}, unit = \"deg\" }}`; if radians are meant, say so with `unit = \"rad\"`",
                p.name
            ));
            self.warnings.push(d);
        }
    }
}
