//! docs/model-format.md stays true: its delta robot, written from the reference alone with
//! rough home values, repetition, joints by name and thin rods, generates (the home assembles,
//! M is positive definite there), and its home holds the arms below the horizontal.

#[test]
fn the_delta_robot_of_the_model_format_reference_generates() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let doc = std::fs::read_to_string(root.join("docs/model-format.md")).unwrap();
    let section = doc
        .split("## A delta robot from scratch")
        .nth(1)
        .expect("docs/model-format.md has the delta section");
    let model = section
        .split("```toml\n")
        .nth(1)
        .and_then(|s| s.split("```").next())
        .expect("the delta section has a toml block");
    assert!(model.contains("[[leg]]") && model.contains("revolute") && model.contains("\"rod\""));
    let generated = rbss_codegen::generate(
        "docs/model-format.md (delta)",
        model,
        &rbss_codegen::Options::default(),
        &mut |_| {},
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let r = &generated.report;
    assert_eq!((r.n, r.m), (12, 9));
    assert!(
        r.home_residual <= 1e-12,
        "home residual {:e}",
        r.home_residual
    );
    assert!(r.warnings.is_empty(), "{}", r.warnings);
    // th1..th3 assembled below the horizontal and the same for the three arms (symmetry).
    for i in 0..3 {
        assert!(
            r.home[i] > 0.0 && r.home[i] < 1.5,
            "th{}: {}",
            i + 1,
            r.home[i]
        );
        assert!((r.home[i] - r.home[0]).abs() < 1e-12);
    }
    assert_eq!(r.home[11], -0.25, "the output z is held");
}
