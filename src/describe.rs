//! `rbss list --model NAME` / `--model-file PATH` (and `--json`): a robot's coordinates `X`,
//! its constraints `f` (by loop and component), the actuated coordinates and the outputs, by
//! name and index: the orders the other commands' vectors use, without reading the generated
//! crate.

use rbss_runtime::{Dynamics, Model};
use serde_json::{Value, json};

/// The description of `model`: a table for people, or JSON (`json`) for programs.
pub fn describe<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    json: bool,
) -> Result<String, String> {
    if json {
        return serde_json::to_string_pretty(&describe_json(model))
            .map_err(|e| format!("cannot write JSON: {e}"));
    }
    let s = model.structure();
    let loops = constraint_loops(s.constraints);
    let mut t = String::new();
    let w = s.coordinates.iter().map(|c| c.len()).max().unwrap_or(0);
    t.push_str(&format!(
        "{}: {N} coordinates, {M} constraints, {} degrees of freedom\n",
        s.name,
        N.saturating_sub(M)
    ));
    t.push_str("coordinates X (index, name, home, roles):\n");
    for (j, c) in s.coordinates.iter().enumerate() {
        let home = s
            .home
            .get(j)
            .map_or(String::new(), |h| format!("{h:>12.6}"));
        t.push_str(&format!(
            "  {j:>3}  {c:<w$}  {home}  {}\n",
            roles(s, j).join(", ")
        ));
    }
    if loops.is_empty() {
        t.push_str("constraints f: none (no loop)\n");
    } else {
        t.push_str("constraints f (by loop: row index and component):\n");
        for (lp, rows) in &loops {
            let items: Vec<String> = rows
                .iter()
                .map(|&i| format!("{i} {}", split_constraint(s.constraints[i]).1))
                .collect();
            t.push_str(&format!("  {lp}: {}\n", items.join(", ")));
        }
    }
    let list = |idx: &[usize]| {
        if idx.is_empty() {
            "none".to_string()
        } else {
            idx.iter()
                .map(|&j| format!("{} (X[{j}])", s.coordinates[j]))
                .collect::<Vec<_>>()
                .join(", ")
        }
    };
    t.push_str(&format!("actuated q: {}\n", list(s.actuated)));
    t.push_str(&format!("outputs y: {}\n", list(s.outputs)));
    Ok(t.trim_end().to_string())
}

/// The roles of coordinate `j`: actuated, output, passive (a passive output is an output).
fn roles(s: &rbss_runtime::Structure, j: usize) -> Vec<&'static str> {
    let mut r = Vec::new();
    if s.actuated.contains(&j) {
        r.push("actuated");
    }
    if s.outputs.contains(&j) {
        r.push("output");
    }
    if s.passive.contains(&j) && !s.outputs.contains(&j) {
        r.push("passive");
    }
    r
}

/// The description of `model` as JSON (what `rbss list --json` prints).
pub fn describe_json<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
) -> Value {
    let s = model.structure();
    let loops = constraint_loops(s.constraints);
    let named = |idx: &[usize]| -> Vec<Value> {
        idx.iter()
            .map(|&j| json!({ "name": s.coordinates[j], "index": j }))
            .collect()
    };
    json!({
        "name": s.name,
        "coordinates": s.coordinates.iter().enumerate().map(|(j, c)| json!({
            "index": j,
            "name": c,
            "roles": roles(s, j),
            "home": s.home.get(j),
        })).collect::<Vec<_>>(),
        "constraints": s.constraints.iter().enumerate().map(|(i, c)| {
            let (lp, component) = split_constraint(c);
            json!({ "index": i, "name": c, "loop": lp, "component": component })
        }).collect::<Vec<_>>(),
        "loops": loops.iter().map(|(lp, rows)| json!({ "name": lp, "rows": rows }))
            .collect::<Vec<_>>(),
        "actuated": s.actuated.iter().enumerate().map(|(i, &j)| json!({
            "name": s.coordinates[j],
            "index": j,
            "gear": rbss_runtime::gear_ratio(s.gear, i),
        })).collect::<Vec<_>>(),
        "outputs": named(s.outputs),
        "passive": named(s.passive),
        "degrees_of_freedom": N.saturating_sub(M),
    })
}

/// A constraint's loop and component: `leg1.x` is component `x` of loop `leg1`; a name without
/// a dot is its own loop with an empty component.
fn split_constraint(name: &str) -> (&str, &str) {
    name.rsplit_once('.').unwrap_or((name, ""))
}

/// The loops of a constraint list in first-appearance order, each with its rows.
fn constraint_loops(constraints: &[&str]) -> Vec<(String, Vec<usize>)> {
    let mut out: Vec<(String, Vec<usize>)> = Vec::new();
    for (i, c) in constraints.iter().enumerate() {
        let lp = split_constraint(c).0;
        match out.iter_mut().find(|(l, _)| l == lp) {
            Some((_, rows)) => rows.push(i),
            None => out.push((lp.to_string(), vec![i])),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constraints_group_by_loop_in_order() {
        let c = ["leg1.x", "leg1.y", "leg2.x", "quat", "leg1.z"];
        let loops = constraint_loops(&c);
        assert_eq!(
            loops,
            vec![
                ("leg1".to_string(), vec![0, 1, 4]),
                ("leg2".to_string(), vec![2]),
                ("quat".to_string(), vec![3]),
            ]
        );
        assert_eq!(split_constraint("a.b.c"), ("a.b", "c"));
    }
}
