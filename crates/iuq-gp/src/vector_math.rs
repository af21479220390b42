//! Vectorised inner loops: a branch-free `exp` and a dispatch macro that compiles a loop once
//! for AVX-512, once for AVX2+FMA and once for the baseline, choosing at run time.
//!
//! Kernel matrices need one `exp` per pair of points (n²/2 per likelihood evaluation, n·m per
//! prediction batch); the scalar libm `exp` costs several nanoseconds, the loop below a fraction
//! of one. The polynomial uses fused multiply-adds (`f64::mul_add`), which are exactly rounded
//! on every code path, so every path returns bit-identical results.

/// Defines a function whose body is compiled for AVX-512, for AVX2+FMA and for the baseline
/// target, and selected at run time by CPU feature detection. The body must be safe code.
macro_rules! multiversion {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident : $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            fn imp($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f,avx2,fma")]
                unsafe fn v4($($arg: $ty),*) $(-> $ret)? { imp($($arg),*) }
                #[target_feature(enable = "avx2,fma")]
                unsafe fn v3($($arg: $ty),*) $(-> $ret)? { imp($($arg),*) }
                if std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: the CPU supports every feature `v4` is compiled for.
                    return unsafe { v4($($arg),*) };
                }
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: the CPU supports every feature `v3` is compiled for.
                    return unsafe { v3($($arg),*) };
                }
            }
            imp($($arg),*)
        }
    };
}
pub(crate) use multiversion;

/// Below this argument `exp` returns exactly 0 (e^−708 ≈ 3.3e−308 is the smallest normal
/// result the scaling step can build).
const EXP_MIN_ARG: f64 = -708.0;
/// Above this argument the result would overflow; arguments are clamped to it.
const EXP_MAX_ARG: f64 = 709.0;
/// 1.5·2⁵²: adding it rounds a double to the nearest integer and leaves that integer in the
/// low mantissa bits.
const ROUNDING_SHIFTER: f64 = 6_755_399_441_055_744.0;
/// ln 2 split in a high part with trailing zero bits (so k·LN2_HI is exact) and the rest
/// (fdlibm's constants).
const LN2_HI: f64 = 6.931_471_803_691_238e-1;
const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
/// Taylor coefficients 1/k!, k = 2..13.
const INV_FACTORIALS: [f64; 12] = [
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5040.0,
    1.0 / 40320.0,
    1.0 / 362_880.0,
    1.0 / 3_628_800.0,
    1.0 / 39_916_800.0,
    1.0 / 479_001_600.0,
    1.0 / 6_227_020_800.0,
];

/// e^x for finite x, branch-free so that loops over it vectorise.
///
/// Range reduction x = k·ln 2 + r, |r| ≤ ln2/2, then e^r by its Taylor polynomial of degree 13
/// (truncation error < r¹⁴/14! ≈ 4e−18, i.e. below half an ulp) evaluated by Horner's rule with
/// fused multiply-adds, and e^x = 2^k·e^r with 2^k built from its bits. Accuracy ≈ 1 ulp;
/// x < −708 gives 0 (the true value is below 3.3e−308), x > 709 is clamped.
#[inline(always)]
pub(crate) fn exp(x: f64) -> f64 {
    let xc = x.clamp(EXP_MIN_ARG, EXP_MAX_ARG);
    let t = xc.mul_add(std::f64::consts::LOG2_E, ROUNDING_SHIFTER);
    let k = t - ROUNDING_SHIFTER;
    let r = k.mul_add(-LN2_LO, k.mul_add(-LN2_HI, xc));
    let mut p = INV_FACTORIALS[11];
    let mut i = 11;
    while i > 0 {
        i -= 1;
        p = p.mul_add(r, INV_FACTORIALS[i]);
    }
    p = p.mul_add(r, 1.0);
    p = p.mul_add(r, 1.0);
    // k as an integer sits in the low bits of t; 2^k = (k + 1023) << 52.
    let k_bits = t.to_bits().wrapping_sub(ROUNDING_SHIFTER.to_bits());
    let scale = f64::from_bits(k_bits.wrapping_add(1023) << 52);
    if x < EXP_MIN_ARG { 0.0 } else { p * scale }
}

multiversion! {
    /// Replaces every value by its exponential ([`exp`]).
    pub(crate) fn exp_in_place(values: &mut [f64]) {
        for v in values.iter_mut() {
            *v = exp(*v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_matches_libm_to_two_ulp() {
        let mut worst: f64 = 0.0;
        let mut xs: Vec<f64> = (0..200_001)
            .map(|i| -700.0 + 705.0 * i as f64 / 200_000.0)
            .collect();
        xs.extend([
            0.0,
            -0.0,
            1e-300,
            -1e-300,
            0.5 * std::f64::consts::LN_2,
            -0.5,
        ]);
        let mut ys = xs.clone();
        exp_in_place(&mut ys);
        for (&x, &y) in xs.iter().zip(&ys) {
            let reference = x.exp();
            let ulp = reference * f64::EPSILON;
            worst = worst.max((y - reference).abs() / ulp);
        }
        assert!(worst <= 2.0, "worst error {worst} ulp");
    }

    #[test]
    fn exp_of_very_negative_is_zero_and_every_path_agrees() {
        let mut v = vec![-708.5, -1e6, -745.2];
        exp_in_place(&mut v);
        assert_eq!(v, vec![0.0, 0.0, 0.0]);
        let xs: Vec<f64> = (0..1000).map(|i| -(i as f64) * 0.37).collect();
        let mut a = xs.clone();
        exp_in_place(&mut a);
        let b: Vec<f64> = xs.iter().map(|&x| exp(x)).collect();
        assert_eq!(a, b);
        assert_eq!(exp(0.0), 1.0);
    }
}
