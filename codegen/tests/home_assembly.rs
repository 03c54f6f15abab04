//! The home configuration needs only a rough guess: rbss-codegen assembles it (Newton on
//! `f(X) = 0` with the outputs held). The paper's 6-UPS with every non-output home value
//! rounded to one decimal (errors up to 0.05 m and 0.05 rad) generates the same assembled home
//! as the model file's 12-digit values, to 1e-12.

fn generate(source: &str) -> rbss_codegen::Report {
    rbss_codegen::generate(
        "models/stewart_6ups.toml",
        source,
        &rbss_codegen::Options::default(),
        &mut |_| {},
    )
    .unwrap_or_else(|e| panic!("{e}"))
    .report
}

#[test]
fn a_rough_home_guess_assembles_to_the_same_configuration() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let source = std::fs::read_to_string(root.join("models/stewart_6ups.toml")).unwrap();
    // Round `home = <number>` of the legs' coordinates (d, phi, psi) to one decimal.
    let rough: String = source
        .lines()
        .map(|line| {
            let leg = ["\"d", "\"phi", "\"psi"].iter().any(|p| line.contains(p));
            match (leg, line.find("home = ")) {
                (true, Some(i)) => {
                    let start = i + "home = ".len();
                    let end = line[start..].find(' ').map_or(line.len(), |e| start + e);
                    let v: f64 = line[start..end].parse().unwrap();
                    format!("{}{:.1}{}", &line[..start], v, &line[end..])
                }
                _ => line.to_string(),
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert_ne!(rough, source, "the rounding changed nothing");
    let exact = generate(&source);
    let assembled = generate(&rough);
    assert!(
        assembled.home_residual < 1e-12,
        "residual {}",
        assembled.home_residual
    );
    for (j, (a, b)) in exact.home.iter().zip(&assembled.home).enumerate() {
        assert!((a - b).abs() < 1e-12, "coordinate {j}: {a} vs {b}");
    }
}
