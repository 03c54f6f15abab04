//! The C example (examples/c/main.c): compiled with the system's C compiler against the 6-UPS
//! library (librbss_stewart_6ups.so, built with the tests as a dev-dependency) through
//! `ffi/include/rbss.h`, run, and its printed numbers checked against the kernels: the
//! inverse-kinematics solution closes the loops, the holding forces hold, and the released
//! accelerations satisfy the equations of motion and the constraints; the derivatives at the
//! held state (forward dynamics' with respect to U, the linearisation A and B, an RK4 step's
//! Jacobians) are the runtime's, and a state off the constraints is refused by rbss_linearize.

use std::path::{Path, PathBuf};
use std::process::Command;

use rbss_runtime::{
    Baumgarte, Coordinates, Data, Dynamics, ForwardDynamicsDerivatives, Kernels, Linearization,
    Model, StepDerivatives, forward_dynamics_derivatives, linearize, rk4_step_derivatives,
};
use stewart_6ups::{M, N, Stewart6Ups};

/// The directory of the library: next to the test binary (`target/release/deps`), where cargo
/// puts a dependency's cdylib.
fn library_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap().to_path_buf();
    let file = format!(
        "{}rbss_stewart_6ups{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    );
    for dir in [deps.clone(), deps.parent().unwrap().to_path_buf()] {
        if dir.join(&file).is_file() {
            return dir;
        }
    }
    panic!(
        "{file} is in neither {} nor its parent: build it with `cargo build --release -p \
         rbss-c-stewart-6ups`",
        deps.display()
    );
}

/// Compiles examples/c/main.c into `dir` and runs it; its stdout.
fn run_example(dir: &Path) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let lib = library_dir();
    let exe = dir.join("robot");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".to_string());
    let out = Command::new(&cc)
        .args(["-O2", "-Wall", "-Wextra", "-Werror", "-std=c11"])
        .arg("-I")
        .arg(root.join("ffi/include"))
        .arg(root.join("examples/c/main.c"))
        .arg("-L")
        .arg(&lib)
        .arg("-lrbss_stewart_6ups")
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-lm")
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap_or_else(|e| panic!("cannot run the C compiler `{cc}` (set CC): {e}"));
    assert!(
        out.status.success(),
        "{cc} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(&exe).output().unwrap();
    assert!(
        run.status.success(),
        "the C example failed:\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    String::from_utf8(run.stdout).unwrap()
}

/// The numbers after `key` on its line.
fn values(stdout: &str, key: &str) -> Vec<f64> {
    let line = stdout
        .lines()
        .find(|l| l.split_whitespace().next() == Some(key))
        .unwrap_or_else(|| panic!("no line `{key}` in\n{stdout}"));
    line.split_whitespace()
        .skip(1)
        .map(|v| v.parse().unwrap())
        .collect()
}

#[test]
fn c_program_solves_ik_and_forward_dynamics_through_the_header() {
    let dir = tempfile::Builder::new()
        .prefix("rbss-c-example-")
        .tempdir()
        .unwrap();
    let stdout = run_example(dir.path());
    assert!(
        stdout.starts_with("robot stewart_6ups n 24 m 18 actuated 6 outputs 6 dynamics 1\n"),
        "{stdout}"
    );
    let robot = Stewart6Ups::default();
    let s = robot.structure();

    // Inverse kinematics: the pose is the solution's outputs, the loops close, q is X's
    // actuated part.
    let pose = values(&stdout, "pose");
    let x: [f64; N] = values(&stdout, "ik.x").try_into().unwrap();
    for (i, &j) in s.outputs.iter().enumerate() {
        assert_eq!(x[j], pose[i], "output {i}");
    }
    let mut f = [0.0; M];
    robot.constraints(&x, &mut f);
    let closure = f.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(closure < 1e-12, "max |f(x)| = {closure:e}");
    let q = values(&stdout, "ik.q");
    for (i, &j) in s.actuated.iter().enumerate() {
        assert_eq!(q[i], x[j]);
    }

    // Held: the forward dynamics under the holding forces is still (to rounding).
    let hold = values(&stdout, "hold.max_abs_xddot")[0];
    assert!(hold < 1e-9, "held robot accelerates: {hold:e}");

    // Released (U = 0, Xdot = 0): G Xddot = gamma = 0 and M Xddot - psi = -G^T lambda for
    // some lambda: the residual of M Xddot - psi projected off the range of G^T is zero. The
    // check: solve G G^T lambda = -G (M Xddot - psi) and take the remainder.
    let xddot: [f64; N] = values(&stdout, "fd.xddot").try_into().unwrap();
    let mut g = [[0.0; M]; N];
    robot.jacobian(&x, &mut g);
    let gx: Vec<f64> = (0..M)
        .map(|i| (0..N).map(|j| g[j][i] * xddot[j]).sum())
        .collect();
    let worst = gx.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(worst < 1e-9, "max |G xddot| = {worst:e}");
    let mut mass = [[0.0; N]; N];
    robot.mass_matrix(&x, &mut mass);
    let mut psi = [0.0; N];
    robot.psi(&x, &[0.0; N], &mut psi);
    let r: Vec<f64> = (0..N)
        .map(|i| (0..N).map(|j| mass[j][i] * xddot[j]).sum::<f64>() - psi[i])
        .collect();
    // Least squares r ~ -G^T lambda by the normal equations (G G^T is 18 x 18, regular here).
    let mut a = vec![vec![0.0; M + 1]; M];
    for (i, row) in a.iter_mut().enumerate() {
        for (k, v) in row.iter_mut().take(M).enumerate() {
            *v = (0..N).map(|j| g[j][i] * g[j][k]).sum();
        }
        row[M] = -(0..N).map(|j| g[j][i] * r[j]).sum::<f64>();
    }
    for c in 0..M {
        let p = (c..M)
            .max_by(|&i, &k| a[i][c].abs().total_cmp(&a[k][c].abs()))
            .unwrap();
        a.swap(c, p);
        for i in 0..M {
            if i != c {
                let factor = a[i][c] / a[c][c];
                let pivot_row = a[c].clone();
                for (v, pv) in a[i].iter_mut().zip(&pivot_row) {
                    *v -= factor * pv;
                }
            }
        }
    }
    let lambda: Vec<f64> = (0..M).map(|i| a[i][M] / a[i][i]).collect();
    let scale = psi.iter().fold(1.0f64, |a, v| a.max(v.abs()));
    for j in 0..N {
        let gtl: f64 = (0..M).map(|i| g[j][i] * lambda[i]).sum();
        let rest = r[j] + gtl;
        assert!(
            rest.abs() < 1e-8 * scale,
            "equation of motion {j} ({}): residual {rest:e}",
            s.coordinates[j]
        );
    }
    // Free fall pulls down: the platform's vertical acceleration is negative.
    let z = s.coordinates.iter().position(|c| *c == "z").unwrap();
    assert!(xddot[z] < -1.0, "z'' = {}", xddot[z]);

    // The derivatives at the held state (xdot = 0, the holding forces), against the runtime's
    // in this process: the same numbers (printed with 17 digits: exact), column-major.
    let u = values(&stdout, "hold.u");
    let model = Model::new(Stewart6Ups::default());
    let mut data = Data::new(&model);
    data.x = x;
    let mut fdd = ForwardDynamicsDerivatives::new();
    forward_dynamics_derivatives(&model, &mut data, &mut fdd, &u, None).unwrap();
    let k = u.len();
    let want: Vec<f64> = (0..k)
        .flat_map(|j| (0..N).map(move |i| (i, j)))
        .map(|ij| fdd.dxddot_du[ij])
        .collect();
    assert_eq!(values(&stdout, "fdd.dxddot_du"), want);
    let want: Vec<f64> = (0..k)
        .flat_map(|j| (0..M).map(move |i| (i, j)))
        .map(|ij| fdd.dlambda_du[ij])
        .collect();
    assert_eq!(values(&stdout, "fdd.dlambda_du"), want);
    let mut data = Data::new(&model);
    data.x = x;
    let mut lin = Linearization::new();
    linearize(&model, &mut data, &mut lin, &u, None, Coordinates::Outputs).unwrap();
    let w = 2 * lin.d;
    let (mut a, mut b) = (vec![0.0; w * w], vec![0.0; w * k]);
    lin.state_space(&mut a, &mut b).unwrap();
    let col_major = |m: &[f64], cols: usize| -> Vec<f64> {
        (0..cols)
            .flat_map(|j| (0..w).map(move |i| m[i * cols + j]))
            .collect()
    };
    assert_eq!(values(&stdout, "lin.A"), col_major(&a, w));
    assert_eq!(values(&stdout, "lin.B"), col_major(&b, k));
    let mut data = Data::new(&model);
    data.x = x;
    let mut st = StepDerivatives::new();
    rk4_step_derivatives(&model, &mut data, &mut st, &u, 1e-3, Baumgarte::NONE).unwrap();
    assert_eq!(values(&stdout, "rk4.x"), st.x);
    assert_eq!(values(&stdout, "rk4.fx"), st.jacobian[..4 * N * N]);
    assert_eq!(
        values(&stdout, "rk4.fu"),
        st.jacobian[4 * N * N..2 * N * (2 * N + k)]
    );
    // Held still, gravity balanced: the platform's rows of A's velocity block are not all zero
    // (the linearisation is not trivial) and B is M's inverse on the outputs, non-zero.
    assert!(b.iter().any(|v| v.abs() > 1e-3), "B = {b:?}");
    assert!(stdout.contains("error.state_code 5\n"), "{stdout}");

    // The error path: a NaN is refused with the argument's name.
    assert!(stdout.contains("error.code 2\n"), "{stdout}");
    assert!(
        stdout.contains("error.message `pose`[0] is not finite (NaN)"),
        "{stdout}"
    );
}
