//! Baumgarte's constraint stabilisation, the gains forward dynamics and the simulator take.

/// Baumgarte's constraint stabilisation in forward dynamics: the acceleration constraint
/// `G Ẍ = gamma` becomes `G Ẍ = gamma - 2 alpha G Ẋ - beta² f(X)`, so that the constraint
/// error `e = f(X)` obeys `ë + 2 alpha ė + beta² e = 0` instead of `ë = 0`.
///
/// `alpha = beta = 0` ([`Baumgarte::NONE`], the default) is the plain index-1 system. With
/// `alpha = beta = ω` the error decays critically damped with time constant `1/ω`; an explicit
/// integrator then needs `ω h` well inside its stability region (RK4 and DOPRI5: about 2.8 and
/// 3.3 on the negative real axis). See [`Baumgarte::DEFAULT`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Baumgarte {
    /// Damping gain `alpha` (1/s).
    pub alpha: f64,
    /// Stiffness gain `beta` (1/s).
    pub beta: f64,
}

impl Baumgarte {
    /// No stabilisation.
    pub const NONE: Self = Self {
        alpha: 0.0,
        beta: 0.0,
    };

    /// `alpha = beta = 10 /s`: critically damped, time constant 0.1 s.
    ///
    /// Why 10, measured on the paper's round trip (`TraekP` over 2 s, feed-forward `U` from
    /// inverse dynamics; `runtime/tests/dynamics.rs`), sweeping `ω` over 1, 2, 5, 10, 20, 50,
    /// 100 /s:
    ///
    /// - the drift comes from integration error, and the violation settles near
    ///   (local error rate) / ω²: at `ω = 10` the largest `|f|` is about 100 times smaller than
    ///   without stabilisation for RK4 (`dt` 1e-2 and 1e-3) and DOPRI5 (rtol 1e-4 to 1e-8);
    /// - but the stabilised system gains a double eigenvalue `-ω` that the integrator must
    ///   resolve: with RK4 at `dt = 1e-2` the violation is smallest at `ω` = 5 to 10 and grows
    ///   again beyond (3e-7 at 50 /s, worse than 1.1e-8 at 10 /s); DOPRI5's error control
    ///   shortens its steps, costing +40 % right-hand-side evaluations at `ω = 10` (rtol 1e-6),
    ///   +110 % at 20 and +330 % at 50.
    pub const DEFAULT: Self = Self {
        alpha: 10.0,
        beta: 10.0,
    };

    /// Critically damped gains `alpha = beta = omega`.
    pub const fn critical(omega: f64) -> Self {
        Self {
            alpha: omega,
            beta: omega,
        }
    }
}

impl Default for Baumgarte {
    fn default() -> Self {
        Self::NONE
    }
}
