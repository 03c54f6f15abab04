//! The loops' structure, checked on the parsed model before anything is derived: every
//! coordinate that is not an output must be moved by some loop (otherwise its column of `G`
//! is zero and inverse kinematics cannot find it). The usual cause is a loop attached to the
//! wrong body (`leg2_upper` written for `leg3_upper`): when an attachment reaches only
//! coordinates that other loops reach too, the error points at it (the one whose body's name
//! is closest to the unreached body's) and the help names the body it should reach. Without
//! such an attachment the derivation reports the problem (a loop that cannot close, or an
//! inverse-kinematics block that is not square).

use super::*;

fn coords_of(steps: &[Step], out: &mut [bool]) {
    for s in steps {
        match s {
            Step::Rot(_, e) | Step::Trans(_, e) => walk(e, out),
            Step::Rotation(m) => m.iter().flatten().for_each(|e| walk(e, out)),
            Step::Quat(q) => q.iter().for_each(|e| walk(e, out)),
        }
    }
}

/// Marks the coordinates an expression reads.
fn walk(e: &Expr, out: &mut [bool]) {
    match e {
        Expr::Coord(j) => {
            if let Some(u) = out.get_mut(*j) {
                *u = true;
            }
        }
        Expr::Num { .. } | Expr::Pi | Expr::Param(_) => {}
        Expr::Neg(a) => walk(a, out),
        Expr::Call(_, args) => args.iter().for_each(|a| walk(a, out)),
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) | Expr::Pow(a, b) => {
            walk(a, out);
            walk(b, out);
        }
    }
}

impl Parser<'_> {
    /// See the module documentation. `sites[l]` are the spans of loop `l`'s `a.body` and
    /// `b.body` values.
    pub(super) fn loop_structure(&mut self, model: &Model, sites: &[[Span; 2]]) {
        let n = model.coordinates.len();
        if sites.len() != model.loops.len() {
            return;
        }
        // Coordinates moving each body's frame (its own steps and its ancestors').
        let mut chain: Vec<Vec<bool>> = Vec::with_capacity(model.bodies.len());
        for b in &model.bodies {
            let mut c = match b.parent {
                Some(p) if p < chain.len() => chain[p].clone(),
                _ => vec![false; n],
            };
            coords_of(&b.steps, &mut c);
            chain.push(c);
        }
        let side = |a: &Attachment| -> Vec<bool> {
            let mut c = a
                .body
                .and_then(|b| chain.get(b).cloned())
                .unwrap_or_else(|| vec![false; n]);
            coords_of(&a.steps, &mut c);
            c
        };
        let sides: Vec<[Vec<bool>; 2]> = model
            .loops
            .iter()
            .map(|l| {
                let mut s = [side(&l.a), side(&l.b)];
                // A coupling's sides are the coordinates of its two expressions.
                if let LoopKind::Coupling { a, b, .. } = &l.kind {
                    walk(a, &mut s[0]);
                    if let Some(b) = b {
                        walk(b, &mut s[1]);
                    }
                }
                // A unit norm's side is its quaternion.
                if let LoopKind::UnitNorm(q) = l.kind {
                    for j in q {
                        if let Some(c) = s[0].get_mut(j) {
                            *c = true;
                        }
                    }
                }
                s
            })
            .collect();
        let mut is_output = vec![false; n];
        for &o in &model.outputs {
            is_output[o] = true;
        }
        let reached = |j: usize, skip: Option<(usize, usize)>| {
            sides.iter().enumerate().any(|(l, s)| {
                s.iter()
                    .enumerate()
                    .any(|(k, c)| Some((l, k)) != skip && c[j])
            })
        };
        let orphans: Vec<usize> = (0..n)
            .filter(|&j| !is_output[j] && !reached(j, None))
            .collect();
        if orphans.is_empty() {
            return;
        }
        // The bodies the orphans move that no other body hangs from: where a loop should attach.
        let has_child: Vec<bool> = (0..model.bodies.len())
            .map(|i| model.bodies.iter().any(|b| b.parent == Some(i)))
            .collect();
        let leaves: Vec<usize> = (0..model.bodies.len())
            .filter(|&i| !has_child[i] && orphans.iter().any(|&j| chain[i][j]))
            .collect();
        let names = |cols: &[usize]| -> String {
            cols.iter()
                .map(|&j| format!("`{}`", model.coordinates[j].name))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let Some(&leaf) = leaves.first() else {
            return;
        };
        let target = &model.bodies[leaf];
        let leaf_orphans: Vec<usize> = orphans
            .iter()
            .copied()
            .filter(|&j| chain[leaf][j])
            .collect();
        // Attachments whose coordinates other loops reach as well: the likely wrong ones.
        // (distance of the body's name to the target's, of the loop's name to it, a later loop
        // first: a copy of an earlier loop is the likelier mistake, loop, side)
        let mut suspects: Vec<(usize, usize, std::cmp::Reverse<usize>, usize, usize)> = Vec::new();
        for (l, lp) in model.loops.iter().enumerate() {
            for (k, att) in [&lp.a, &lp.b].into_iter().enumerate() {
                let Some(b) = att.body else { continue };
                let own: Vec<usize> = (0..n)
                    .filter(|&j| sides[l][k][j] && !is_output[j])
                    .collect();
                if own.is_empty() || !own.iter().all(|&j| reached(j, Some((l, k)))) {
                    continue;
                }
                let dist = edit_distance(&model.bodies[b].name, &target.name).unwrap_or(usize::MAX);
                let by_loop = edit_distance(&lp.name, &target.name).unwrap_or(usize::MAX);
                suspects.push((dist, by_loop, std::cmp::Reverse(l), l, k));
            }
        }
        suspects.sort();
        // Without an attachment to blame, the derivation reports the problem.
        if let Some(&(_, _, _, l, k)) = suspects.first() {
            let lp = &model.loops[l];
            let att = if k == 0 { &lp.a } else { &lp.b };
            let wrong = att.body.map_or("world", |b| model.bodies[b].name.as_str());
            let others: Vec<String> = model
                .loops
                .iter()
                .enumerate()
                .filter(|&(o, _)| o != l)
                .filter(|&(o, _)| {
                    (0..n).any(|j| {
                        sides[l][k][j] && !is_output[j] && (sides[o][0][j] || sides[o][1][j])
                    })
                })
                .map(|(_, o)| format!("`{}`", o.name))
                .collect();
            let site = sites[l][k].clone();
            let d = self.cx.error(
                    &site,
                    format!(
                        "no loop reaches body `{}`: its coordinates {} are in no loop, and `{}` of loop `{}` is attached to `{wrong}`, which loop{} {} already close{}",
                        target.name,
                        names(&leaf_orphans),
                        ["a", "b"][k],
                        lp.name,
                        if others.len() == 1 { "" } else { "s" },
                        others.join(", "),
                        if others.len() == 1 { "s" } else { "" },
                    ),
                    format!("attached to `{wrong}`"),
                );
            d.help = Some(format!(
                "did you mean `body = \"{}\"`? every coordinate that is not an output must be moved by a loop",
                target.name
            ));
        }
    }
}
