//! C2 cubic splines with not-a-knot end conditions, evaluated with their exact first and second
//! derivatives.
//!
//! Why not-a-knot rather than natural: a natural spline forces `s'' = 0` at both ends, so
//! wherever the trajectory accelerates at its first or last sample (TraekP does, everywhere)
//! the spline's acceleration there is wrong by the whole `|x''|`, an O(1) error that decays only
//! over a few intervals. Not-a-knot (the third derivative continuous at the second and the
//! second-last knot) asks nothing of the ends: the error of `s''` is O(h²) up to the ends, and
//! a cubic polynomial is reproduced exactly (from 4 samples on).

/// One spline through `(t_i, y_i)`: its second derivatives `m_i` at the knots.
#[derive(Debug, Clone)]
pub struct Spline {
    y: Vec<f64>,
    m: Vec<f64>,
}

impl Spline {
    /// The not-a-knot spline through `(t[i], y[i])`; `t` strictly increasing, `t.len() ==
    /// y.len() >= 2`. Two samples give the straight line, three the parabola through them.
    pub fn not_a_knot(t: &[f64], y: &[f64]) -> Spline {
        let n = t.len().min(y.len());
        let y = y[..n].to_vec();
        let mut m = vec![0.0; n];
        if n == 3 {
            let d0 = (y[1] - y[0]) / (t[1] - t[0]);
            let d1 = (y[2] - y[1]) / (t[2] - t[1]);
            let c = 2.0 * (d1 - d0) / (t[2] - t[0]);
            m.fill(c);
        } else if n >= 4 {
            let h: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
            let d: Vec<f64> = (0..n - 1).map(|i| (y[i + 1] - y[i]) / h[i]).collect();
            // Unknowns m_1 .. m_{n-2}: row i is
            //   h_{i-1} m_{i-1} + 2 (h_{i-1} + h_i) m_i + h_i m_{i+1} = 6 (d_i - d_{i-1}),
            // with m_0 and m_{n-1} eliminated by the not-a-knot conditions
            //   (m_1 - m_0) / h_0 = (m_2 - m_1) / h_1, and the same at the right end.
            let k = n - 2;
            let mut sub = vec![0.0; k];
            let mut diag = vec![0.0; k];
            let mut sup = vec![0.0; k];
            let mut rhs = vec![0.0; k];
            for r in 0..k {
                let i = r + 1;
                sub[r] = h[i - 1];
                diag[r] = 2.0 * (h[i - 1] + h[i]);
                sup[r] = h[i];
                rhs[r] = 6.0 * (d[i] - d[i - 1]);
            }
            let (h0, h1) = (h[0], h[1]);
            diag[0] = (h0 + h1) * (h0 + 2.0 * h1) / h1;
            sup[0] = (h1 * h1 - h0 * h0) / h1;
            sub[0] = 0.0;
            let (a, b) = (h[n - 3], h[n - 2]);
            diag[k - 1] = (a + b) * (2.0 * a + b) / a;
            sub[k - 1] = (a * a - b * b) / a;
            sup[k - 1] = 0.0;
            // Thomas algorithm: the matrix is diagonally dominant (the modified end rows too:
            // (h0 + h1)(h0 + 2 h1) >= |h1² - h0²|), so no pivoting is needed.
            for r in 1..k {
                let w = sub[r] / diag[r - 1];
                diag[r] -= w * sup[r - 1];
                rhs[r] -= w * rhs[r - 1];
            }
            m[k] = rhs[k - 1] / diag[k - 1];
            for r in (0..k - 1).rev() {
                m[r + 1] = (rhs[r] - sup[r] * m[r + 2]) / diag[r];
            }
            m[0] = ((h0 + h1) * m[1] - h0 * m[2]) / h1;
            m[n - 1] = ((a + b) * m[n - 2] - b * m[n - 3]) / a;
        }
        Spline { y, m }
    }

    /// `s(x)`, `s'(x)`, `s''(x)` on the knots `t` the spline was built on (outside `[t_0,
    /// t_{n-1}]` the end cubics are extended).
    pub fn eval(&self, t: &[f64], x: f64) -> (f64, f64, f64) {
        let n = self.y.len();
        if n < 2 {
            return (self.y.first().copied().unwrap_or(f64::NAN), 0.0, 0.0);
        }
        let i = t[..n]
            .partition_point(|&k| k <= x)
            .saturating_sub(1)
            .min(n - 2);
        let h = t[i + 1] - t[i];
        let u = x - t[i];
        let (m0, m1) = (self.m[i], self.m[i + 1]);
        let dm = (m1 - m0) / h;
        let slope = (self.y[i + 1] - self.y[i]) / h - h * (2.0 * m0 + m1) / 6.0;
        let s = self.y[i] + u * (slope + u * (0.5 * m0 + u * dm / 6.0));
        let s1 = slope + u * (m0 + 0.5 * u * dm);
        let s2 = m0 + u * dm;
        (s, s1, s2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uneven knots: a cubic comes back exactly, with its derivatives, inside and at the knots.
    #[test]
    fn reproduces_a_cubic_on_uneven_knots() {
        let p = |x: f64| {
            (
                2.0 - 3.0 * x + 0.5 * x * x - 1.25 * x * x * x,
                -3.0 + x - 3.75 * x * x,
                1.0 - 7.5 * x,
            )
        };
        for n in [4usize, 5, 9, 30] {
            let t: Vec<f64> = (0..n)
                .map(|i| i as f64 / (n - 1) as f64 * 2.0 - 0.7 + 0.03 * ((i * 7) % 5) as f64)
                .collect();
            let y: Vec<f64> = t.iter().map(|&x| p(x).0).collect();
            let s = Spline::not_a_knot(&t, &y);
            for k in 0..=200 {
                let x = t[0] + (t[n - 1] - t[0]) * k as f64 / 200.0;
                let (a, b, c) = s.eval(&t, x);
                let (pa, pb, pc) = p(x);
                assert!(
                    (a - pa).abs() < 1e-12 && (b - pb).abs() < 1e-11 && (c - pc).abs() < 1e-10,
                    "n = {n}, x = {x}: {a} {b} {c} vs {pa} {pb} {pc}"
                );
            }
        }
    }

    #[test]
    fn few_samples_give_a_line_and_a_parabola() {
        let s = Spline::not_a_knot(&[0.0, 2.0], &[1.0, 5.0]);
        assert_eq!(s.eval(&[0.0, 2.0], 0.5), (2.0, 2.0, 0.0));
        let t = [0.0, 1.0, 3.0];
        let s = Spline::not_a_knot(&t, &[0.0, 1.0, 9.0]);
        let (a, b, c) = s.eval(&t, 2.0);
        assert!((a - 4.0).abs() < 1e-14 && (b - 4.0).abs() < 1e-14 && (c - 2.0).abs() < 1e-14);
    }
}
