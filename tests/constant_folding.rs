//! Constants fold exactly: models/five_bar_turned.toml is five_bar's mechanism written with
//! redundant constant rotations (`Ry(pi / 2) ... Ry(-pi / 2)`, `Rx(pi) ... Rx(pi)`, a quarter
//! turn given in degrees) and unusual parameter names. Every constant rotation must fold away:
//! frozen, the two generate kernels with exactly the same operation counts; with run-time
//! parameters, the same trigonometry (no `sin`/`cos` of a constant left in a kernel; the
//! degree-valued turn is a parameter, read from `Params::consts`). That the generated crate is
//! clippy-clean is checked by CI's `cargo clippy --workspace -- -D warnings` (it is a member).

use rbss_codegen::{Options, Report, generate};

fn report(path: &str, freeze: bool) -> Report {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let source = std::fs::read_to_string(root.join(path)).unwrap();
    let opts = Options {
        freeze,
        ..Options::default()
    };
    generate(path, &source, &opts, &mut |_| {})
        .unwrap_or_else(|e| panic!("{e}"))
        .report
}

#[test]
fn constant_rotations_fold_away() {
    for freeze in [true, false] {
        let plain = report("models/five_bar.toml", freeze);
        let turned = report("models/five_bar_turned.toml", freeze);
        for (a, b) in plain.kernels.iter().zip(&turned.kernels) {
            assert_eq!(a.name, b.name);
            assert_eq!(a.nonzeros, b.nonzeros, "{}: structural non-zeros", a.name);
            if freeze {
                assert_eq!(a.ops, b.ops, "{} (frozen): {} vs {}", a.name, a.ops, b.ops);
            } else {
                assert_eq!(
                    a.ops.func, b.ops.func,
                    "{}: trigonometry of constants left in the kernel ({} vs {})",
                    a.name, a.ops, b.ops
                );
            }
        }
    }
}

/// The kernels agree numerically too (same coordinates, same values): a folded constant is
/// the exact value, not an approximation that happens to have the same operation count.
#[test]
fn turned_five_bar_computes_the_same_kernels() {
    use rbss_runtime::Kernels;
    let (a, b) = (
        five_bar::FiveBar::default(),
        five_bar_turned::FiveBarTurned::default(),
    );
    let x = [1.9, -1.4, 1.2, 1.5, 0.01, 0.29];
    let (mut fa, mut fb) = ([0.0; 4], [0.0; 4]);
    a.constraints(&x, &mut fa);
    b.constraints(&x, &mut fb);
    let (mut ga, mut gb) = ([[0.0; 4]; 6], [[0.0; 4]; 6]);
    a.jacobian(&x, &mut ga);
    b.jacobian(&x, &mut gb);
    for i in 0..4 {
        assert!(
            (fa[i] - fb[i]).abs() < 1e-15,
            "f[{i}]: {} vs {}",
            fa[i],
            fb[i]
        );
        for j in 0..6 {
            assert!((ga[j][i] - gb[j][i]).abs() < 1e-15, "G[{i}][{j}]");
        }
    }
}
