//! Scaling that keeps `f32` arithmetic in range: a vector or a box far from unit size (1e20,
//! 1e-23) is brought near 1 before anything is squared, and brought back after. Powers of two
//! scale exactly, so wherever nothing over- or underflowed the results are bit for bit those of
//! the unscaled values.

use glam::Vec3;

/// The power of two `s` with `m s` in [1, 2) (`s` = 2^127 for subnormal `m`, which reaches
/// (0, 2)); `None` for a zero, negative, infinite or NaN `m`.
pub fn power_of_two_scale(m: f32) -> Option<f32> {
    if !(m > 0.0 && m.is_finite()) {
        return None;
    }
    // The biased exponent `e` (0 for subnormals) makes `m` about 2^(e - 127); 2^(127 - e) has
    // the biased exponent 254 - e, or is the subnormal 2^-127 for e = 254.
    let e = (m.to_bits() >> 23) & 0xff;
    Some(if e == 254 {
        f32::from_bits(1 << 22)
    } else {
        f32::from_bits((254 - e) << 23)
    })
}

/// `v` scaled to unit length, or `None` for a zero or non-finite vector. Divided by its largest
/// component first: `Vec3::normalize` squares the components, which overflows past about 1e19
/// and underflows below about 1e-19.
pub fn unit(v: Vec3) -> Option<Vec3> {
    let m = v.abs().max_element();
    if !(m > 0.0 && m.is_finite()) {
        return None;
    }
    let u = (v / m).normalize();
    u.is_finite().then_some(u)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every positive finite `f32`, sampled across its exponents, lands in [1, 2) (subnormals
    /// in (0, 2)), by an exact power of two.
    #[test]
    fn scales_are_powers_of_two_into_one_to_two() {
        let mut m = f32::from_bits(1);
        while m.is_finite() {
            for x in [m, m * 1.7, f32::from_bits(m.to_bits() | 0x7f_ffff)] {
                if !x.is_finite() {
                    continue;
                }
                let s = power_of_two_scale(x).unwrap();
                assert_eq!(
                    s.to_bits() & 0x7f_ffff & (s.to_bits() - 1),
                    0,
                    "{s} not 2^k"
                );
                let y = x * s;
                let want = if x.is_normal() { 1.0..2.0 } else { 0.0..2.0 };
                assert!(want.contains(&y), "{x:e} scaled by {s:e} is {y}");
            }
            m *= 2.0;
        }
        for bad in [0.0, -1.0, f32::INFINITY, f32::NAN] {
            assert_eq!(power_of_two_scale(bad), None, "{bad}");
        }
    }
}
