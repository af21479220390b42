//! The instruction set of the row kernels, chosen at run time (AVX-512, AVX2 with FMA, or
//! scalar), the dispatch to the kernel compiled for it, and the x86 vector types.

use super::numbers::Stored;
use super::sweep::{Fields, SharedBuffer, even_row_with, odd_row_with};

/// The instruction set the row kernel is compiled for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Simd {
    #[cfg(all(target_arch = "x86_64", iuq_avx512))]
    Avx512,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    Scalar,
}

impl Simd {
    pub(super) fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            // A diagnostic override (results are identical on every path).
            let choice = std::env::var("IUQ_RBC_SIMD").unwrap_or_default();
            if choice == "scalar" {
                return Simd::Scalar;
            }
            #[cfg(iuq_avx512)]
            if choice != "avx2" && std::arch::is_x86_feature_detected!("avx512f") {
                return Simd::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Simd::Avx2;
            }
        }
        Simd::Scalar
    }

    pub(super) fn name(self) -> &'static str {
        match self {
            #[cfg(all(target_arch = "x86_64", iuq_avx512))]
            Simd::Avx512 => "avx512f",
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => "avx2+fma",
            Simd::Scalar => "scalar",
        }
    }
}

/// Even step of one row, in place: collide and write into the opposite slots.
pub(super) fn even_row<S: Stored>(fields: &Fields, r: usize, row: &mut [S], simd: Simd) {
    match simd {
        #[cfg(all(target_arch = "x86_64", iuq_avx512))]
        // SAFETY: `Simd::Avx512` is only chosen when the CPU reports AVX-512F.
        Simd::Avx512 => unsafe { x86::avx512::even_row(fields, r, row) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::Avx2` is only chosen when the CPU reports AVX2 and FMA.
        Simd::Avx2 => unsafe { x86::even_row_avx2(fields, r, row) },
        Simd::Scalar => even_row_with::<f64, S>(fields, r, row),
    }
}

/// Odd step of one row: gather from the neighbours, collide, scatter to the neighbours.
pub(super) fn odd_row<S: Stored>(fields: &Fields, f: &SharedBuffer<S>, r: usize, simd: Simd) {
    match simd {
        #[cfg(all(target_arch = "x86_64", iuq_avx512))]
        // SAFETY: `Simd::Avx512` is only chosen when the CPU reports AVX-512F.
        Simd::Avx512 => unsafe { x86::avx512::odd_row(fields, f, r) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::Avx2` is only chosen when the CPU reports AVX2 and FMA.
        Simd::Avx2 => unsafe { x86::odd_row_avx2(fields, f, r) },
        Simd::Scalar => odd_row_with::<f64, S>(fields, f, r),
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    //! AVX2 vectors (4 lanes) and the row kernel compiled for them. (AVX-512 intrinsics need
    //! Rust 1.89, above the workspace's minimum; on the shear box the update is bound by memory,
    //! not by vector width.)
    use crate::lattice::numbers::{Real, Stored, Vector};
    use crate::lattice::sweep::{Fields, SharedBuffer, even_row_with, odd_row_with};
    use std::arch::x86_64::*;

    macro_rules! vector {
        ($name:ident, $t:ty, $lanes:expr, $set1:ident, $add:ident, $sub:ident, $mul:ident,
         $div:ident, $fmadd:ident, $loadu:ident, $storeu:ident, $cvt_up:ident, $loadu_s:ident,
         $cvt_down:ident, $storeu_s:ident) => {
            /// A SIMD register of f64 lanes. Its operations are only reached from the row
            /// kernel compiled for (and dispatched after detecting) the instruction set.
            #[derive(Clone, Copy)]
            pub(super) struct $name($t);
            impl std::ops::Add for $name {
                type Output = Self;
                #[inline(always)]
                fn add(self, o: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $add(self.0, o.0) })
                }
            }
            impl std::ops::Sub for $name {
                type Output = Self;
                #[inline(always)]
                fn sub(self, o: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $sub(self.0, o.0) })
                }
            }
            impl std::ops::Mul for $name {
                type Output = Self;
                #[inline(always)]
                fn mul(self, o: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $mul(self.0, o.0) })
                }
            }
            impl std::ops::Div for $name {
                type Output = Self;
                #[inline(always)]
                fn div(self, o: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $div(self.0, o.0) })
                }
            }
            impl std::ops::Neg for $name {
                type Output = Self;
                #[inline(always)]
                fn neg(self) -> Self {
                    Self::splat(0.0) - self
                }
            }
            impl Real for $name {
                #[inline(always)]
                fn splat(v: f64) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $set1(v) })
                }
                #[inline(always)]
                fn fma(a: Self, b: Self, c: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $fmadd(a.0, b.0, c.0) })
                }
            }
            impl Vector for $name {
                const LANES: usize = $lanes;
                #[inline(always)]
                fn load(s: &[f64]) -> Self {
                    let s = &s[..$lanes];
                    // SAFETY: `s` holds LANES values (the slice is bounds checked).
                    Self(unsafe { $loadu(s.as_ptr()) })
                }
                #[inline(always)]
                fn load_single(s: &[f32]) -> Self {
                    let s = &s[..$lanes];
                    // SAFETY: `s` holds LANES values (the slice is bounds checked).
                    Self(unsafe { $cvt_up($loadu_s(s.as_ptr())) })
                }
                #[inline(always)]
                fn gather(value: impl Fn(usize) -> f64) -> Self {
                    let a: [f64; $lanes] = std::array::from_fn(value);
                    Self::load(&a)
                }
                #[inline(always)]
                fn store(self, out: &mut [f64], width: usize) {
                    if width == $lanes {
                        let out = &mut out[..$lanes];
                        // SAFETY: `out` holds LANES values (the slice is bounds checked).
                        unsafe { $storeu(out.as_mut_ptr(), self.0) };
                    } else {
                        let mut a = [0.0; $lanes];
                        // SAFETY: `a` holds LANES values.
                        unsafe { $storeu(a.as_mut_ptr(), self.0) };
                        out[..width].copy_from_slice(&a[..width]);
                    }
                }
                #[inline(always)]
                fn prefetch<T>(p: *const T) {
                    // SAFETY: a prefetch never faults.
                    unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast::<i8>()) };
                }
                #[inline(always)]
                fn spill(self, out: &mut [f64; 8]) {
                    // SAFETY: `out` holds at least LANES values; the feature was detected.
                    unsafe { $storeu(out.as_mut_ptr(), self.0) };
                }
                #[inline(always)]
                unsafe fn load_ptr(p: *const f64) -> Self {
                    // SAFETY: forwarded from the caller; the feature was detected.
                    Self(unsafe { $loadu(p) })
                }
                #[inline(always)]
                unsafe fn load_single_ptr(p: *const f32) -> Self {
                    // SAFETY: forwarded from the caller; the feature was detected.
                    Self(unsafe { $cvt_up($loadu_s(p)) })
                }
                #[inline(always)]
                unsafe fn store_ptr(self, p: *mut f64) {
                    // SAFETY: forwarded from the caller; the feature was detected.
                    unsafe { $storeu(p, self.0) }
                }
                #[inline(always)]
                unsafe fn store_single_ptr(self, p: *mut f32) {
                    // SAFETY: forwarded from the caller; the feature was detected.
                    unsafe { $storeu_s(p, $cvt_down(self.0)) }
                }
                #[inline(always)]
                fn store_single(self, out: &mut [f32], width: usize) {
                    // SAFETY: the instruction set was detected before dispatch.
                    let narrow = unsafe { $cvt_down(self.0) };
                    if width == $lanes {
                        let out = &mut out[..$lanes];
                        // SAFETY: `out` holds LANES values (the slice is bounds checked).
                        unsafe { $storeu_s(out.as_mut_ptr(), narrow) };
                    } else {
                        let mut a = [0.0f32; $lanes];
                        // SAFETY: `a` holds LANES values.
                        unsafe { $storeu_s(a.as_mut_ptr(), narrow) };
                        out[..width].copy_from_slice(&a[..width]);
                    }
                }
            }
        };
    }
    vector!(
        Avx2,
        __m256d,
        4,
        _mm256_set1_pd,
        _mm256_add_pd,
        _mm256_sub_pd,
        _mm256_mul_pd,
        _mm256_div_pd,
        _mm256_fmadd_pd,
        _mm256_loadu_pd,
        _mm256_storeu_pd,
        _mm256_cvtps_pd,
        _mm_loadu_ps,
        _mm256_cvtpd_ps,
        _mm_storeu_ps
    );

    /// AVX-512 vectors (8 lanes) and the row kernels compiled for them; built only by compilers
    /// that have the AVX-512 intrinsics (Rust ≥ 1.89, see `build.rs`).
    #[cfg(iuq_avx512)]
    #[allow(clippy::incompatible_msrv)]
    pub(super) mod avx512 {
        use crate::lattice::numbers::{Real, Stored, Vector};
        use crate::lattice::sweep::{Fields, SharedBuffer, even_row_with, odd_row_with};
        use std::arch::x86_64::*;

        vector!(
            Avx512,
            __m512d,
            8,
            _mm512_set1_pd,
            _mm512_add_pd,
            _mm512_sub_pd,
            _mm512_mul_pd,
            _mm512_div_pd,
            _mm512_fmadd_pd,
            _mm512_loadu_pd,
            _mm512_storeu_pd,
            _mm512_cvtps_pd,
            _mm256_loadu_ps,
            _mm512_cvtpd_ps,
            _mm256_storeu_ps
        );

        /// The even-step row kernel compiled for AVX-512F.
        ///
        /// # Safety
        /// The CPU must support AVX-512F.
        #[target_feature(enable = "avx512f")]
        pub(in super::super) unsafe fn even_row<S: Stored>(
            fields: &Fields,
            r: usize,
            row: &mut [S],
        ) {
            even_row_with::<Avx512, S>(fields, r, row);
        }

        /// The odd-step row kernel compiled for AVX-512F.
        ///
        /// # Safety
        /// The CPU must support AVX-512F.
        #[target_feature(enable = "avx512f")]
        pub(in super::super) unsafe fn odd_row<S: Stored>(
            fields: &Fields,
            f: &SharedBuffer<S>,
            r: usize,
        ) {
            odd_row_with::<Avx512, S>(fields, f, r);
        }
    }

    /// The even-step row kernel compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn even_row_avx2<S: Stored>(fields: &Fields, r: usize, row: &mut [S]) {
        even_row_with::<Avx2, S>(fields, r, row);
    }

    /// The odd-step row kernel compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn odd_row_avx2<S: Stored>(fields: &Fields, f: &SharedBuffer<S>, r: usize) {
        odd_row_with::<Avx2, S>(fields, f, r);
    }
}
