//! Levenberg–Marquardt's damping, shared by forward kinematics by LM and the reach search.

/// Levenberg–Marquardt's damping `mu` with Nielsen's update from the gain ratio `rho`:
/// `mu *= max(1/3, 1 - (2 rho - 1)³)` on an accepted step, `mu *= nu, nu *= 2` on a rejected
/// one (forward kinematics by LM, and the reach search after a failed IK).
pub(crate) struct Damping {
    /// The damping; `0` until the caller sets it from the first `JᵀJ`.
    pub mu: f64,
    nu: f64,
}

impl Damping {
    pub fn new() -> Self {
        Self { mu: 0.0, nu: 2.0 }
    }

    /// An accepted step with gain ratio `rho > 0`.
    pub fn accept(&mut self, rho: f64) {
        let t = 2.0 * rho - 1.0;
        self.mu = (self.mu * (1.0 / 3.0_f64).max(1.0 - t * t * t)).max(1e-300);
        self.nu = 2.0;
    }

    /// A rejected step (no decrease, or the damped system could not be solved).
    pub fn reject(&mut self) {
        self.mu *= self.nu;
        self.nu *= 2.0;
    }
}
