//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

pub mod golden;
pub mod kkt;
pub mod la3;
pub mod robot_lib;

/// A small deterministic generator (xorshift64*), so every run sees the same states.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.max(1))
    }
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in [-1, 1).
    pub fn sym(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// The two platforms of `stewart_2stage` (as in benches/kernels.rs): platform 1 on TraekP,
/// platform 2 0.56 m above it with a sway of its own, `x2 = x1 + 0.02 sin(2wt)`; pose, rate and
/// acceleration.
pub fn two_stage(t: f64) -> [[f64; 12]; 3] {
    use rbss::paper::{OMEGA, traek_p};
    let w = OMEGA;
    let (p, v, a) = traek_p(t, w);
    let (s2, c2) = (2.0 * w * t).sin_cos();
    let mut out = [[0.0; 12]; 3];
    for (o, d) in out.iter_mut().zip([p, v, a]) {
        o[..6].copy_from_slice(&d);
        o[6..].copy_from_slice(&d);
    }
    out[0][8] += 0.56;
    out[0][6] += 0.02 * s2;
    out[1][6] += 0.04 * w * c2;
    out[2][6] -= 0.08 * w * w * s2;
    out
}

/// Runs the `rbss` command with `args` from the package root: (success, stdout, stderr).
pub fn rbss(args: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rbss"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// `max |a_k - b_k|`.
pub fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0, |m: f64, (x, y)| m.max((x - y).abs()))
}

/// `|a - b| <= rel (|a| + |b|) + abs`, with a message naming the entry.
#[track_caller]
pub fn assert_close(what: &str, a: f64, b: f64, rel: f64, abs: f64) {
    assert!(
        (a - b).abs() <= rel * (a.abs() + b.abs()) + abs && a.is_finite(),
        "{what}: kernel {a:e}, numeric {b:e}, diff {:e}",
        a - b
    );
}

/// Solves the 3 × 3 system `a x = b` by Cramer's rule.
pub fn solve3(a: &[[f64; 3]; 3], b: &[f64; 3]) -> [f64; 3] {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    std::array::from_fn(|k| {
        let mut m = *a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        det(&m) / d
    })
}

/// The actuator forces that hold the robot at rest, by virtual work on the closed form alone:
/// `U . dq = dV` along the mechanism, with `q(o)` and `V(o)` functions of the three outputs
/// `o`, so `J^T U = grad V` with `J = dq/do` (central differences, step 1e-6).
pub fn static_forces(
    o: &[f64; 3],
    q: impl Fn(&[f64; 3]) -> [f64; 3],
    v: impl Fn(&[f64; 3]) -> f64,
) -> [f64; 3] {
    let h = 1e-6;
    let mut jt = [[0.0; 3]; 3];
    let mut grad = [0.0; 3];
    for k in 0..3 {
        let (mut op, mut om) = (*o, *o);
        op[k] += h;
        om[k] -= h;
        let (qp, qm) = (q(&op), q(&om));
        for r in 0..3 {
            jt[k][r] = (qp[r] - qm[r]) / (2.0 * h);
        }
        grad[k] = (v(&op) - v(&om)) / (2.0 * h);
    }
    solve3(&jt, &grad)
}
