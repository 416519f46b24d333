//! Platform-exact arithmetic: sin and cos from fixed polynomials and small
//! vector helpers.

/// sin and cos from fixed polynomials, identical on every platform (libm is not).
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    const PIO2_HI: f64 = 1.570_796_326_734_125_6;
    const PIO2_LO: f64 = 6.077_100_506_506_192e-11;
    let k = (x * std::f64::consts::FRAC_2_PI).round();
    let r = (x - k * PIO2_HI) - k * PIO2_LO;
    let r2 = r * r;
    let mut s = 0.0;
    let mut c = 0.0;
    // Taylor series to degree 17/16; |r| <= pi/4 keeps the error below 1e-16.
    let mut fact = 1.0f64;
    let mut sc = [0.0f64; 9];
    let mut cc = [0.0f64; 9];
    for i in 0..9 {
        let n = 2 * i as u32;
        if i > 0 {
            fact *= ((n - 1) * n) as f64;
        }
        cc[i] = if i % 2 == 0 { 1.0 / fact } else { -1.0 / fact };
        let fs = fact * (n + 1) as f64;
        sc[i] = if i % 2 == 0 { 1.0 / fs } else { -1.0 / fs };
    }
    for i in (0..9).rev() {
        s = s * r2 + sc[i];
        c = c * r2 + cc[i];
    }
    s *= r;
    match (k as i64).rem_euclid(4) {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

pub(crate) type V3 = [f64; 3];

pub(crate) fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_cos_matches_libm_closely() {
        for i in -2000..2000 {
            let x = i as f64 * 0.0123;
            let (s, c) = sin_cos(x);
            assert!((s - x.sin()).abs() < 1e-15, "{x}");
            assert!((c - x.cos()).abs() < 1e-15, "{x}");
        }
    }
}
