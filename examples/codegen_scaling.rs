//! How code generation scales with the size of the robot: generation time and operation counts
//! of the kernels against the number of bodies, for
//!
//! - an N-link spatial chain (N = 2 .. 50): revolute joints about alternating y and x axes,
//!   links of 0.3 m, each link's tip height read by an output coordinate (one loop per link, so
//!   `G` is lower-triangular: N(N+1)/2 non-zeros whatever the derivation), and
//! - a stack of k 6-UPS stages (k = 1 .. 4), each standing on the previous stage's platform.
//!
//! ```text
//! cargo run --release --example codegen_scaling -- --out docs
//! ```
//! writes `codegen_scaling.csv` and `codegen_scaling.png` (log-log) to the directory and prints
//! the fitted slopes (least squares of log ops on log bodies, over every size and over the
//! larger half) as a markdown table. `--model chain:N` (or `stack:K`) prints one study model to
//! stdout instead, to time `rbss-codegen` on it alone.

use std::path::PathBuf;
use std::time::Instant;

use rbss::plot::{Panel, Series, write_png};

/// The N-link chain as a model file.
fn chain(n: usize) -> String {
    let mut s = String::new();
    s.push_str("coordinates = [\n");
    for i in 1..=n {
        s.push_str(&format!(
            "  {{ name = \"th{i}\", unit = \"rad\", home = 0.3 }},\n"
        ));
    }
    for i in 1..=n {
        s.push_str(&format!(
            "  {{ name = \"z{i}\", unit = \"m\", home = 0.2 }},\n"
        ));
    }
    s.push_str("]\n\n[robot]\n");
    s.push_str(&format!(
        "name = \"chain_{n}\"\ndescription = \"{n}-link spatial chain (scaling study)\"\n"
    ));
    s.push_str("gravity = [0, 0, -9.81]\n");
    let list = |p: &str| {
        (1..=n)
            .map(|i| format!("\"{p}{i}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    s.push_str(&format!(
        "actuated = [{}]\noutputs = [{}]\n\n",
        list("th"),
        list("z")
    ));
    s.push_str("[parameters]\nl = { value = 0.3, unit = \"m\" }\nr = { value = 0.02, unit = \"m\" }\nrho = { value = 2700, unit = \"kg/m^3\" }\n\n");
    for i in 1..=n {
        let axis = if i % 2 == 1 { "Ry" } else { "Rx" };
        let (parent, tr) = if i == 1 {
            ("world".to_string(), format!("[\"{axis}(th1)\"]"))
        } else {
            (
                format!("link{}", i - 1),
                format!("[\"Tz(l)\", \"{axis}(th{i})\"]"),
            )
        };
        s.push_str(&format!(
            "[[body]]\nname = \"link{i}\"\nparent = \"{parent}\"\ntransforms = {tr}\n\
             solid = {{ shape = \"cylinder\", radius = \"r\", length = \"l\", density = \"rho\" }}\n\
             com = [0, 0, \"l / 2\"]\n\n"
        ));
    }
    for i in 1..=n {
        s.push_str(&format!(
            "[[loop]]\nname = \"tip{i}\"\na = {{ body = \"link{i}\", transforms = [\"Tz(l)\"] }}\n\
             b = {{ body = \"world\", transforms = [\"Tz(z{i})\"] }}\ncomponents = [\"z\"]\n\n"
        ));
    }
    s
}

/// k 6-UPS stages in series, each on the previous platform (the paper's geometry for all).
fn stack(k: usize) -> String {
    let mut s = String::from("coordinates = [\n");
    let legs = 6 * k;
    for (p, unit, home) in [("d", "m", 0.95), ("phi", "rad", 0.1), ("psi", "rad", -0.1)] {
        for j in 1..=legs {
            s.push_str(&format!(
                "  {{ name = \"{p}{j}\", unit = \"{unit}\", home = {home} }},\n"
            ));
        }
    }
    for st in 1..=k {
        for (p, unit, home) in [
            ("x", "m", 0.0),
            ("y", "m", 0.0),
            ("z", "m", 0.94 * st as f64),
            ("rotx", "rad", 0.0),
            ("roty", "rad", 0.0),
            ("rotz", "rad", 0.0),
        ] {
            s.push_str(&format!(
                "  {{ name = \"{p}{st}\", unit = \"{unit}\", home = {home} }},\n"
            ));
        }
    }
    s.push_str("]\n\n[robot]\n");
    s.push_str(&format!(
        "name = \"stack_{k}\"\ndescription = \"{k} 6-UPS stages in series (scaling study)\"\n"
    ));
    s.push_str("gravity = [0, 0, -9.81]\n");
    let act: Vec<String> = (1..=legs).map(|j| format!("\"d{j}\"")).collect();
    let out: Vec<String> = (1..=k)
        .flat_map(|st| ["x", "y", "z", "rotx", "roty", "rotz"].map(|p| format!("\"{p}{st}\"")))
        .collect();
    s.push_str(&format!(
        "actuated = [{}]\noutputs = [{}]\n\n",
        act.join(", "),
        out.join(", ")
    ));
    s.push_str(
        "[parameters]\nr0 = { value = 0.489, unit = \"m\" }\nrp = { value = 0.389, unit = \"m\" }\n\
         rho = { value = 7800, unit = \"kg/m^3\" }\nr_lower = { value = 0.05, unit = \"m\" }\n\
         l_lower = { value = 0.5, unit = \"m\" }\nr_upper = { value = 0.04, unit = \"m\" }\n\
         l_upper = { value = 0.8, unit = \"m\" }\nt_platform = { value = 0.02, unit = \"m\" }\n",
    );
    let alpha = [-15, 15, 105, 135, 225, 255];
    let beta = [-45, 45, 75, 165, 195, 285];
    for i in 0..6 {
        s.push_str(&format!(
            "alpha{} = {{ value = {}, unit = \"deg\" }}\nbeta{} = {{ value = {}, unit = \"deg\" }}\n",
            i + 1,
            alpha[i],
            i + 1,
            beta[i]
        ));
    }
    s.push('\n');
    for st in 1..=k {
        for i in 1..=6 {
            let j = 6 * (st - 1) + i;
            let parent = if st == 1 {
                "world".to_string()
            } else {
                format!("platform{}", st - 1)
            };
            s.push_str(&format!(
                "[[body]]\nname = \"leg{j}_lower\"\nparent = \"{parent}\"\n\
                 transforms = [\"Rz(alpha{i})\", \"Tx(r0)\", \"Rx(phi{j})\", \"Ry(psi{j})\"]\n\
                 solid = {{ shape = \"cylinder\", radius = \"r_lower\", length = \"l_lower\", density = \"rho\" }}\n\
                 com = [0, 0, \"l_lower / 2\"]\n\n\
                 [[body]]\nname = \"leg{j}_upper\"\nparent = \"leg{j}_lower\"\ntransforms = [\"Tz(d{j})\"]\n\
                 solid = {{ shape = \"cylinder\", radius = \"r_upper\", length = \"l_upper\", density = \"rho\" }}\n\
                 com = [0, 0, \"-l_upper / 2\"]\n\n"
            ));
        }
        s.push_str(&format!(
            "[[body]]\nname = \"platform{st}\"\n\
             transforms = [[\"x{st}\", \"y{st}\", \"z{st}\", \"rotx{st}\", \"roty{st}\", \"rotz{st}\", 1, 2, 3, 4, 5, 6]]\n\
             solid = {{ shape = \"cylinder\", radius = \"rp\", length = \"t_platform\", density = \"rho\" }}\n\
             com = [0, 0, 0]\n\n"
        ));
        for i in 1..=6 {
            let j = 6 * (st - 1) + i;
            s.push_str(&format!(
                "[[loop]]\nname = \"leg{j}\"\na = {{ body = \"leg{j}_upper\" }}\n\
                 b = {{ body = \"platform{st}\", transforms = [\"Rz(beta{i})\", \"Tx(rp)\"] }}\n\n"
            ));
        }
    }
    s
}

const KERNELS: [(&str, &str); 6] = [
    ("constraints", "f"),
    ("jacobian", "G"),
    ("gamma", "gamma"),
    ("mass_matrix", "M"),
    ("psi", "psi"),
    ("dynamics_terms", "dynamics_terms"),
];

struct Row {
    family: &'static str,
    size: usize,
    bodies: usize,
    n: usize,
    m: usize,
    seconds: f64,
    lines: usize,
    /// mul + add + div + fn per kernel of KERNELS.
    ops: Vec<f64>,
    /// Structural non-zeros of `G` (the chain's grow as N²/2 by its design: one loop per tip).
    g_nonzeros: usize,
}

fn measure(family: &'static str, size: usize, source: &str) -> Row {
    let path = format!("<{family} {size}>");
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..3 {
        let t0 = Instant::now();
        let g = rbss_codegen::generate(
            &path,
            source,
            &rbss_codegen::Options::default(),
            &mut |_| {},
        )
        .unwrap_or_else(|e| panic!("{e}"));
        best = best.min(t0.elapsed().as_secs_f64());
        last = Some(g);
    }
    let g = last.expect("three runs");
    let r = &g.report;
    let ops = KERNELS
        .iter()
        .map(|(k, _)| {
            let o = r
                .kernels
                .iter()
                .find(|x| x.name == *k)
                .unwrap_or_else(|| panic!("no kernel {k}"))
                .ops;
            (o.mul + o.add + o.div + o.func) as f64
        })
        .collect();
    let bodies = source.matches("[[body]]").count();
    let g_nonzeros = r
        .kernels
        .iter()
        .find(|x| x.name == "jacobian")
        .map_or(0, |x| x.nonzeros);
    Row {
        family,
        size,
        bodies,
        n: r.n,
        m: r.m,
        seconds: best,
        lines: r.lines,
        ops,
        g_nonzeros,
    }
}

/// Least-squares slope of log y on log x.
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let lx: Vec<f64> = x.iter().map(|v| v.ln()).collect();
    let ly: Vec<f64> = y.iter().map(|v| v.ln()).collect();
    let k = lx.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / k, ly.iter().sum::<f64>() / k);
    let sxy: f64 = lx.iter().zip(&ly).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = lx.iter().map(|a| (a - mx) * (a - mx)).sum();
    sxy / sxx
}

fn main() -> Result<(), String> {
    let mut out = PathBuf::from("docs");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = PathBuf::from(args.next().ok_or("--out needs a directory")?),
            "--model" => {
                // Print one study model (`chain:N` or `stack:K`) to stdout, for rbss-codegen.
                let spec = args.next().ok_or("--model needs chain:N or stack:K")?;
                let (family, size) = spec
                    .split_once(':')
                    .ok_or("--model needs chain:N or stack:K")?;
                let size: usize = size.parse().map_err(|e| format!("--model {spec}: {e}"))?;
                match family {
                    "chain" => print!("{}", chain(size)),
                    "stack" => print!("{}", stack(size)),
                    _ => return Err(format!("--model {spec}: the family is chain or stack")),
                }
                return Ok(());
            }
            other => {
                return Err(format!(
                    "unknown argument `{other}`; usage: codegen_scaling [--out DIR | --model chain:N | --model stack:K]"
                ));
            }
        }
    }
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut rows = Vec::new();
    for n in [2, 4, 6, 8, 12, 16, 24, 32, 40, 50] {
        let r = measure("chain", n, &chain(n));
        eprintln!(
            "chain N = {n:2}: {} bodies, n = {}, m = {}, {:.3} s, {} lines, ops {:?}",
            r.bodies, r.n, r.m, r.seconds, r.lines, r.ops
        );
        rows.push(r);
    }
    for k in 1..=4 {
        let r = measure("stack", k, &stack(k));
        eprintln!(
            "stack k = {k}: {} bodies, n = {}, m = {}, {:.3} s, {} lines, ops {:?}",
            r.bodies, r.n, r.m, r.seconds, r.lines, r.ops
        );
        rows.push(r);
    }

    // CSV: family (0 chain, 1 stack), size, bodies, n, m, seconds, lines, ops...
    let mut header: Vec<String> = ["family", "size", "bodies", "n", "m", "generate_s", "lines"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    header.extend(KERNELS.iter().map(|(k, _)| format!("ops_{k}")));
    header.push("nonzeros_jacobian".to_string());
    let table: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            let mut v = vec![
                if r.family == "chain" { 0.0 } else { 1.0 },
                r.size as f64,
                r.bodies as f64,
                r.n as f64,
                r.m as f64,
                r.seconds,
                r.lines as f64,
            ];
            v.extend(&r.ops);
            v.push(r.g_nonzeros as f64);
            v
        })
        .collect();
    rbss::csv::write(&out.join("codegen_scaling.csv"), &header, &table)?;

    let mut panels = Vec::new();
    println!("(slopes of log ops on log bodies: all sizes / larger half)");
    println!(
        "| family | generation at the largest size | {} |",
        KERNELS.map(|k| k.1).join(" | ")
    );
    println!("|---|---|{}", "---|".repeat(KERNELS.len()));
    for family in ["chain", "stack"] {
        let fam: Vec<&Row> = rows.iter().filter(|r| r.family == family).collect();
        let x: Vec<f64> = fam.iter().map(|r| r.bodies as f64).collect();
        let mut panel = Panel::new(
            if family == "chain" {
                "N-link chain: operations per kernel"
            } else {
                "k stacked 6-UPS stages: operations per kernel"
            },
            "bodies",
            "mul + add + div + fn",
        )
        .log_x()
        .log_y();
        // Slopes over every size and over the larger half (the asymptotic regime: small models
        // take the body-by-body form of the dynamics, large chains the recursive one).
        let half = fam.len() / 2;
        let mut slopes = Vec::new();
        for (i, (_, short)) in KERNELS.iter().enumerate() {
            let y: Vec<f64> = fam.iter().map(|r| r.ops[i]).collect();
            let s = slope(&x, &y);
            let s_big = slope(&x[half..], &y[half..]);
            slopes.push(format!("{s:.2} / {s_big:.2}"));
            panel = panel
                .with(Series::new(format!("{short} (slope {s_big:.2})"), x.clone(), y).markers());
        }
        let last = fam.last().expect("sizes");
        println!(
            "| {family} ({} bodies, n = {}) | {:.3} s | {} |",
            last.bodies,
            last.n,
            last.seconds,
            slopes.join(" | ")
        );
        panels.push(panel);
    }
    // G's cost per entry: its ops against its structural non-zeros (1 = a constant cost per
    // entry, whatever the number of entries the model's loops give it).
    println!("\n(slope of log ops(G) on log non-zeros(G): all sizes / larger half)");
    for family in ["chain", "stack"] {
        let fam: Vec<&Row> = rows.iter().filter(|r| r.family == family).collect();
        let x: Vec<f64> = fam.iter().map(|r| r.g_nonzeros as f64).collect();
        let y: Vec<f64> = fam.iter().map(|r| r.ops[1]).collect();
        let half = fam.len() / 2;
        let last = fam.last().expect("sizes");
        println!(
            "| {family} | G non-zeros {} -> {} | {:.2} / {:.2} |",
            fam[0].g_nonzeros,
            last.g_nonzeros,
            slope(&x, &y),
            slope(&x[half..], &y[half..])
        );
    }
    let mut time = Panel::new("generation time (best of 3)", "bodies", "seconds")
        .log_x()
        .log_y();
    for family in ["chain", "stack"] {
        let fam: Vec<&Row> = rows.iter().filter(|r| r.family == family).collect();
        let x: Vec<f64> = fam.iter().map(|r| r.bodies as f64).collect();
        let y: Vec<f64> = fam.iter().map(|r| r.seconds).collect();
        let s = slope(&x, &y);
        time = time.with(Series::new(format!("{family} (slope {s:.2})"), x, y).markers());
    }
    panels.push(time);
    write_png(
        &out.join("codegen_scaling.png"),
        "rbss-codegen: operations and generation time against the number of bodies",
        &panels,
        3,
        1800,
        600,
    )?;
    eprintln!(
        "wrote {0}/codegen_scaling.csv and {0}/codegen_scaling.png",
        out.display()
    );
    Ok(())
}
