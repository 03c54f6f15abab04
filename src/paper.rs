//! The paper's example (../shared/paper-example.md): the platform motion `TraekP` of the
//! 6-UPS robot, with its exact first and second time derivatives.

/// `w` of the paper's example, rad/s (assumed there: the paper gives no value).
pub const OMEGA: f64 = std::f64::consts::PI;
/// The motion runs over `t` in `[0, T_END]` s (one period).
pub const T_END: f64 = 2.0;

/// Platform pose `[x, y, z, rotx, roty, rotz]` and its first and second time derivatives at
/// time `t` for angular frequency `w`:
///
/// ```text
/// x = 0.1 cos(wt)   y = 0.1 sin(wt)   z = 0.94 (1 + 0.01 sin(3wt))
/// rotx = 0.1 cos(2wt)   roty = 0.1 sin(2wt)   rotz = 0.1 cos(2wt) sin(2wt) = 0.05 sin(4wt)
/// ```
pub fn traek_p(t: f64, w: f64) -> ([f64; 6], [f64; 6], [f64; 6]) {
    let (s1, c1) = (w * t).sin_cos();
    let (s2, c2) = (2.0 * w * t).sin_cos();
    let (s3, c3) = (3.0 * w * t).sin_cos();
    let (s4, c4) = (4.0 * w * t).sin_cos();
    let pos = [
        0.1 * c1,
        0.1 * s1,
        0.94 * (1.0 + 0.01 * s3),
        0.1 * c2,
        0.1 * s2,
        0.05 * s4,
    ];
    let vel = [
        -0.1 * w * s1,
        0.1 * w * c1,
        0.94 * 0.03 * w * c3,
        -0.2 * w * s2,
        0.2 * w * c2,
        0.2 * w * c4,
    ];
    let w2 = w * w;
    let acc = [
        -0.1 * w2 * c1,
        -0.1 * w2 * s1,
        -0.94 * 0.09 * w2 * s3,
        -0.4 * w2 * c2,
        -0.4 * w2 * s2,
        -0.8 * w2 * s4,
    ];
    (pos, vel, acc)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed-form derivatives against central differences of the pose.
    #[test]
    fn derivatives_match_differences() {
        let h = 1e-5;
        for k in 0..50 {
            let t = k as f64 * 0.04;
            let (_, v, a) = traek_p(t, OMEGA);
            let (pp, vp, _) = traek_p(t + h, OMEGA);
            let (pm, vm, _) = traek_p(t - h, OMEGA);
            for i in 0..6 {
                assert!(
                    ((pp[i] - pm[i]) / (2.0 * h) - v[i]).abs() < 1e-8,
                    "velocity {i} at t = {t}"
                );
                assert!(
                    ((vp[i] - vm[i]) / (2.0 * h) - a[i]).abs() < 1e-7,
                    "acceleration {i} at t = {t}"
                );
            }
        }
    }
}
