//! Second-order hyper-dual numbers: forward-mode automatic differentiation of an expression
//! of one variable, exact up to rounding (the trajectories' velocities and accelerations).

use crate::Func;

/// A second-order hyper-dual number `v + d1 ε₁ + d1 ε₂ + d2 ε₁ε₂` (with `ε₁² = ε₂² = 0`) for
/// one variable: seeded with `t + ε₁ + ε₂`, a function `f` maps it to
/// `f(t) + f'(t) (ε₁ + ε₂) + f''(t) ε₁ε₂`. Both `ε` parts are equal for a function of one
/// variable, so one field `d1` holds them; the arithmetic is the hyper-dual one, exact up to
/// rounding (no truncation error).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HyperDual {
    /// `f(t)`.
    pub v: f64,
    /// `f'(t)`.
    pub d1: f64,
    /// `f''(t)`.
    pub d2: f64,
}

impl HyperDual {
    /// A constant: both derivatives zero.
    pub fn constant(v: f64) -> Self {
        HyperDual {
            v,
            d1: 0.0,
            d2: 0.0,
        }
    }

    /// The variable itself at `t`: `t + ε₁ + ε₂`.
    pub fn variable(t: f64) -> Self {
        HyperDual {
            v: t,
            d1: 1.0,
            d2: 0.0,
        }
    }

    /// `g(self)` from `g(v)`, `g'(v)` and `g''(v)` (the chain rule to second order).
    fn chain(self, g: f64, g1: f64, g2: f64) -> Self {
        HyperDual {
            v: g,
            d1: g1 * self.d1,
            d2: g2 * self.d1 * self.d1 + g1 * self.d2,
        }
    }

    fn is_constant(self) -> bool {
        self.d1 == 0.0 && self.d2 == 0.0
    }

    pub fn recip(self) -> Self {
        let r = 1.0 / self.v;
        self.chain(r, -r * r, 2.0 * r * r * r)
    }

    /// `self^e`: with a constant exponent `p` the power rule (integer `p` accepts a negative
    /// base), otherwise `exp(e ln self)`.
    pub fn pow(self, e: Self) -> Self {
        if !e.is_constant() {
            return (self.ln() * e).exp();
        }
        let p = e.v;
        if p == 0.0 {
            return HyperDual::constant(1.0);
        }
        if p == 1.0 {
            return self;
        }
        if p.fract() == 0.0 && p.abs() <= i32::MAX as f64 {
            let n = p as i32;
            // n >= 2 or n <= -1: u^(n-2) is finite wherever u^n is (u != 0 for n < 0).
            let u = self.v;
            let um2 = u.powi(n - 2);
            return self.chain(u.powi(n), p * u * um2, p * (p - 1.0) * um2);
        }
        let u = self.v;
        self.chain(
            u.powf(p),
            p * u.powf(p - 1.0),
            p * (p - 1.0) * u.powf(p - 2.0),
        )
    }

    pub fn sin(self) -> Self {
        let (s, c) = self.v.sin_cos();
        self.chain(s, c, -s)
    }

    pub fn cos(self) -> Self {
        let (s, c) = self.v.sin_cos();
        self.chain(c, -s, -c)
    }

    pub fn tan(self) -> Self {
        let t = self.v.tan();
        let sec2 = 1.0 + t * t;
        self.chain(t, sec2, 2.0 * t * sec2)
    }

    pub fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e, e)
    }

    pub fn ln(self) -> Self {
        let r = 1.0 / self.v;
        self.chain(self.v.ln(), r, -r * r)
    }

    pub fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, 0.5 / s, -0.25 / (s * self.v))
    }

    pub fn asin(self) -> Self {
        let r = 1.0 / (1.0 - self.v * self.v);
        let g1 = r.sqrt();
        self.chain(self.v.asin(), g1, self.v * r * g1)
    }

    pub fn acos(self) -> Self {
        let r = 1.0 / (1.0 - self.v * self.v);
        let g1 = r.sqrt();
        self.chain(self.v.acos(), -g1, -self.v * r * g1)
    }

    /// `|self|`; at 0 the derivative is taken as 0.
    pub fn abs(self) -> Self {
        let s = if self.v > 0.0 {
            1.0
        } else if self.v < 0.0 {
            -1.0
        } else {
            0.0
        };
        self.chain(self.v.abs(), s, 0.0)
    }

    /// `atan2(self, x)`: with `N = x y' - y x'` and `D = x² + y²`, the derivative is `N / D`
    /// and the second `(N' D - N D') / D²`, `N' = x y'' - y x''`, `D' = 2 (x x' + y y')`.
    pub fn atan2(self, x: Self) -> Self {
        let y = self;
        let d = x.v * x.v + y.v * y.v;
        let n = x.v * y.d1 - y.v * x.d1;
        let n1 = x.v * y.d2 - y.v * x.d2;
        let d1 = 2.0 * (x.v * x.d1 + y.v * y.d1);
        HyperDual {
            v: y.v.atan2(x.v),
            d1: n / d,
            d2: (n1 * d - n * d1) / (d * d),
        }
    }

    /// `hypot(self, y) = h`: `h' = (x x' + y y') / h`,
    /// `h'' = (x'² + x x'' + y'² + y y'') / h - (x x' + y y')² / h³`.
    pub fn hypot(self, y: Self) -> Self {
        let x = self;
        let h = x.v.hypot(y.v);
        let s = x.v * x.d1 + y.v * y.d1;
        let s1 = x.d1 * x.d1 + x.v * x.d2 + y.d1 * y.d1 + y.v * y.d2;
        HyperDual {
            v: h,
            d1: s / h,
            d2: s1 / h - s * s / (h * h * h),
        }
    }
}

impl Func {
    /// The function of hyper-dual arguments: its value and derivatives by the chain rule.
    pub fn dual(self, args: &[HyperDual]) -> HyperDual {
        let nan = HyperDual::constant(f64::NAN);
        let a = args.first().copied().unwrap_or(nan);
        let b = args.get(1).copied().unwrap_or(nan);
        match self {
            Func::Sin => a.sin(),
            Func::Cos => a.cos(),
            Func::Tan => a.tan(),
            Func::Exp => a.exp(),
            Func::Ln => a.ln(),
            Func::Sqrt => a.sqrt(),
            Func::Atan2 => a.atan2(b),
            Func::Asin => a.asin(),
            Func::Acos => a.acos(),
            Func::Hypot => a.hypot(b),
            Func::Abs => a.abs(),
        }
    }
}

impl std::ops::Add for HyperDual {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        HyperDual {
            v: self.v + o.v,
            d1: self.d1 + o.d1,
            d2: self.d2 + o.d2,
        }
    }
}

impl std::ops::Sub for HyperDual {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        HyperDual {
            v: self.v - o.v,
            d1: self.d1 - o.d1,
            d2: self.d2 - o.d2,
        }
    }
}

impl std::ops::Neg for HyperDual {
    type Output = Self;
    fn neg(self) -> Self {
        HyperDual {
            v: -self.v,
            d1: -self.d1,
            d2: -self.d2,
        }
    }
}

impl std::ops::Mul for HyperDual {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        HyperDual {
            v: self.v * o.v,
            d1: self.d1 * o.v + self.v * o.d1,
            d2: self.d2 * o.v + 2.0 * self.d1 * o.d1 + self.v * o.d2,
        }
    }
}

impl std::ops::Div for HyperDual {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        if o.is_constant() {
            let r = 1.0 / o.v;
            HyperDual {
                v: self.v * r,
                d1: self.d1 * r,
                d2: self.d2 * r,
            }
        } else {
            self * o.recip()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every function's hyper-dual derivatives against central differences of its f64 value
    /// along a curve of one variable (each argument a different smooth function of t).
    #[test]
    fn derivatives_match_finite_differences() {
        let arg = |k: usize, t: f64| -> HyperDual {
            // 0.3 + 0.4 sin(1.3 t + k), a smooth argument in (-0.1, 0.7).
            let v = HyperDual::variable(t);
            let w = v * HyperDual::constant(1.3) + HyperDual::constant(k as f64);
            HyperDual::constant(0.3) + HyperDual::constant(0.4) * w.sin()
        };
        for f in Func::ALL {
            for &t in &[0.2, 0.9, 1.7] {
                let val = |t: f64| {
                    let args: Vec<f64> = (0..f.arity()).map(|k| arg(k, t).v).collect();
                    f.eval(&args)
                };
                let args: Vec<HyperDual> = (0..f.arity()).map(|k| arg(k, t)).collect();
                let r = f.dual(&args);
                assert_eq!(r.v, val(t), "{}", f.name());
                let h = 1e-4;
                let d1 = (val(t + h) - val(t - h)) / (2.0 * h);
                let d2 = (val(t + h) - 2.0 * val(t) + val(t - h)) / (h * h);
                let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol * (1.0 + a.abs());
                assert!(
                    close(r.d1, d1, 1e-7),
                    "{}'({t}): {} vs {d1}",
                    f.name(),
                    r.d1
                );
                assert!(
                    close(r.d2, d2, 1e-5),
                    "{}''({t}): {} vs {d2}",
                    f.name(),
                    r.d2
                );
            }
        }
    }
}
