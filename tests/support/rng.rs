//! The tests' deterministic random numbers: the library's SplitMix64 ([`rt2::rng::Rng`]), so
//! every run sees the same scenes and rays, with the draws only tests need.

use glam::Vec3;

pub use rt2::rng::Rng;

/// Draws the tests make beyond the library's.
pub trait Draws {
    /// Uniform in `0..n`.
    fn below(&mut self, n: usize) -> usize;
    /// Uniform in the box `[lo, hi)³`.
    fn vec(&mut self, lo: f32, hi: f32) -> Vec3;
    /// Uniform in the unit ball, not the origin.
    fn ball(&mut self) -> Vec3;
    /// A uniform unit direction (from the ball's points at least 0.01 from the origin).
    fn dir(&mut self) -> Vec3;
}

impl Draws for Rng {
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    fn ball(&mut self) -> Vec3 {
        loop {
            let v = self.vec(-1.0, 1.0);
            if v.length_squared() <= 1.0 && v != Vec3::ZERO {
                return v;
            }
        }
    }

    fn dir(&mut self) -> Vec3 {
        loop {
            let v = self.vec(-1.0, 1.0);
            if (1e-4..=1.0).contains(&v.length_squared()) {
                return v.normalize();
            }
        }
    }
}
