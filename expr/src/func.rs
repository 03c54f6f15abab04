//! The function table: every function an expression may call, with its arity, its f64 value
//! and its domain. Adding a function here adds it to models and trajectories alike (its
//! derivatives go in `dual.rs`, its exact folding and code in rbss-codegen's graph).

/// A built-in function.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Func {
    Sin,
    Cos,
    Tan,
    Exp,
    /// The natural logarithm.
    Ln,
    Sqrt,
    /// `atan2(y, x)`: the angle of the point `(x, y)`, in `(-pi, pi]`.
    Atan2,
    Asin,
    Acos,
    /// `hypot(x, y) = sqrt(x^2 + y^2)`.
    Hypot,
    Abs,
}

impl Func {
    /// Every function, in the order messages list them.
    pub const ALL: [Func; 11] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Exp,
        Func::Ln,
        Func::Sqrt,
        Func::Atan2,
        Func::Asin,
        Func::Acos,
        Func::Hypot,
        Func::Abs,
    ];

    /// Their names, in the order of [`Func::ALL`].
    pub const NAMES: [&'static str; 11] = [
        "sin", "cos", "tan", "exp", "ln", "sqrt", "atan2", "asin", "acos", "hypot", "abs",
    ];

    pub fn name(self) -> &'static str {
        Func::NAMES[Func::ALL.iter().position(|f| *f == self).unwrap_or(0)]
    }

    pub fn from_name(name: &str) -> Option<Func> {
        Func::NAMES
            .iter()
            .position(|n| *n == name)
            .map(|i| Func::ALL[i])
    }

    /// The number of arguments.
    pub fn arity(self) -> usize {
        match self {
            Func::Atan2 | Func::Hypot => 2,
            _ => 1,
        }
    }

    /// How it is called, for messages: `atan2(y, x)`, `sin(a)`.
    pub fn signature(self) -> &'static str {
        match self {
            Func::Sin => "sin(a)",
            Func::Cos => "cos(a)",
            Func::Tan => "tan(a)",
            Func::Exp => "exp(a)",
            Func::Ln => "ln(a)",
            Func::Sqrt => "sqrt(a)",
            Func::Atan2 => "atan2(y, x)",
            Func::Asin => "asin(a)",
            Func::Acos => "acos(a)",
            Func::Hypot => "hypot(x, y)",
            Func::Abs => "abs(a)",
        }
    }

    /// The value in f64 (std's functions). `args` has [`Func::arity`] entries; a missing one
    /// reads as NaN.
    pub fn eval(self, args: &[f64]) -> f64 {
        let a = args.first().copied().unwrap_or(f64::NAN);
        let b = args.get(1).copied().unwrap_or(f64::NAN);
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

    /// Why `args` are outside the function's real domain (`asin(2)`, `ln(0)`, `atan2(0, 0)`),
    /// or `None`. Poles of `tan` are not detected here (in f64 `tan(pi / 2)` is finite; a model
    /// folds them exactly).
    pub fn domain_error(self, args: &[f64]) -> Option<String> {
        let a = args.first().copied().unwrap_or(f64::NAN);
        let b = args.get(1).copied().unwrap_or(f64::NAN);
        let name = self.name();
        match self {
            Func::Asin | Func::Acos if a.abs() > 1.0 => Some(format!(
                "the argument of `{name}` must lie in [-1, 1], found {a}"
            )),
            Func::Sqrt if a < 0.0 => Some(format!(
                "the argument of `sqrt` must not be negative, found {a}"
            )),
            Func::Ln if a <= 0.0 => {
                Some(format!("the argument of `ln` must be positive, found {a}"))
            }
            Func::Atan2 if a == 0.0 && b == 0.0 => {
                Some("`atan2(0, 0)` has no angle: the point is the origin".to_string())
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_values_are_std() {
        for f in Func::ALL {
            assert_eq!(Func::from_name(f.name()), Some(f));
            assert!(f.signature().starts_with(f.name()));
            assert_eq!(f.signature().matches(',').count() + 1, f.arity());
        }
        assert_eq!(Func::from_name("atan"), None);
        assert_eq!(Func::Atan2.eval(&[1.0, -1.0]), 1f64.atan2(-1.0));
        assert_eq!(Func::Hypot.eval(&[3.0, 4.0]), 5.0);
        assert_eq!(Func::Abs.eval(&[-2.5]), 2.5);
        assert!(Func::Asin.domain_error(&[2.0]).is_some());
        assert!(Func::Acos.domain_error(&[-1.0]).is_none());
        assert!(Func::Atan2.domain_error(&[0.0, 0.0]).is_some());
        assert!(Func::Ln.domain_error(&[0.0]).is_some());
    }
}
