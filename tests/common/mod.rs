//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

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

/// `|a - b| <= rel (|a| + |b|) + abs`, with a message naming the entry.
#[track_caller]
pub fn assert_close(what: &str, a: f64, b: f64, rel: f64, abs: f64) {
    assert!(
        (a - b).abs() <= rel * (a.abs() + b.abs()) + abs && a.is_finite(),
        "{what}: kernel {a:e}, numeric {b:e}, diff {:e}",
        a - b
    );
}
