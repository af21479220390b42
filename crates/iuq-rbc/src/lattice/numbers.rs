//! The number types of the kernels: [`Real`] (the collision's arithmetic), [`Vector`] (a SIMD
//! vector of node values, or one `f64`) and [`Stored`] (the `f32` or `f64` storage format).

/// The arithmetic the collision needs, for one value (`f64`) or a SIMD vector of values.
pub(super) trait Real:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
{
    fn splat(v: f64) -> Self;
    /// `a·b + c` with a single rounding.
    fn fma(a: Self, b: Self, c: Self) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn splat(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn fma(a: Self, b: Self, c: Self) -> Self {
        a.mul_add(b, c)
    }
}

/// A SIMD vector of `LANES` node values.
pub(super) trait Vector: Real {
    const LANES: usize;
    /// Load `LANES` values from `s[..LANES]`.
    fn load(s: &[f64]) -> Self;
    /// Load `LANES` single-precision values from `s[..LANES]`, widened.
    fn load_single(s: &[f32]) -> Self;
    /// Build a vector lane by lane.
    fn gather(value: impl Fn(usize) -> f64) -> Self;
    /// Store the first `width` lanes into `out[..width]`.
    fn store(self, out: &mut [f64], width: usize);
    /// Store the first `width` lanes, rounded to single precision, into `out[..width]`.
    fn store_single(self, out: &mut [f32], width: usize);
    /// Copy the lanes into `out[..LANES]`.
    fn spill(self, out: &mut [f64; 8]);
    /// Load `LANES` values from `p`.
    ///
    /// # Safety
    /// `p..p + LANES` must be valid for reads.
    unsafe fn load_ptr(p: *const f64) -> Self;
    /// Load `LANES` single-precision values from `p`, widened.
    ///
    /// # Safety
    /// `p..p + LANES` must be valid for reads.
    unsafe fn load_single_ptr(p: *const f32) -> Self;
    /// Store the lanes at `p`.
    ///
    /// # Safety
    /// `p..p + LANES` must be valid for writes.
    unsafe fn store_ptr(self, p: *mut f64);
    /// Store the lanes, rounded to single precision, at `p`.
    ///
    /// # Safety
    /// `p..p + LANES` must be valid for writes.
    unsafe fn store_single_ptr(self, p: *mut f32);
    /// Hint that the cache line at `p` will be read soon.
    fn prefetch<T>(_p: *const T) {}
}

impl Vector for f64 {
    const LANES: usize = 1;
    #[inline(always)]
    fn load(s: &[f64]) -> Self {
        s[0]
    }
    #[inline(always)]
    fn load_single(s: &[f32]) -> Self {
        s[0] as f64
    }
    #[inline(always)]
    fn gather(value: impl Fn(usize) -> f64) -> Self {
        value(0)
    }
    #[inline(always)]
    fn store(self, out: &mut [f64], _width: usize) {
        out[0] = self;
    }
    #[inline(always)]
    fn store_single(self, out: &mut [f32], _width: usize) {
        out[0] = self as f32;
    }
    #[inline(always)]
    fn spill(self, out: &mut [f64; 8]) {
        out[0] = self;
    }
    #[inline(always)]
    unsafe fn load_ptr(p: *const f64) -> Self {
        // SAFETY: the caller guarantees `p` is valid for reads.
        unsafe { *p }
    }
    #[inline(always)]
    unsafe fn load_single_ptr(p: *const f32) -> Self {
        // SAFETY: the caller guarantees `p` is valid for reads.
        unsafe { *p as f64 }
    }
    #[inline(always)]
    unsafe fn store_ptr(self, p: *mut f64) {
        // SAFETY: the caller guarantees `p` is valid for writes.
        unsafe { *p = self }
    }
    #[inline(always)]
    unsafe fn store_single_ptr(self, p: *mut f32) {
        // SAFETY: the caller guarantees `p` is valid for writes.
        unsafe { *p = self as f32 }
    }
}

/// A stored population format.
pub(super) trait Stored: Copy + Send + Sync {
    fn to_f64(self) -> f64;
    fn from_f64(v: f64) -> Self;
    fn load<V: Vector>(s: &[Self]) -> V;
    fn store<V: Vector>(v: V, out: &mut [Self], width: usize);
    /// # Safety
    /// `p..p + V::LANES` must be valid for reads.
    unsafe fn load_ptr<V: Vector>(p: *const Self) -> V;
    /// # Safety
    /// `p..p + V::LANES` must be valid for writes.
    unsafe fn store_ptr<V: Vector>(v: V, p: *mut Self);
}

impl Stored for f64 {
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline(always)]
    unsafe fn load_ptr<V: Vector>(p: *const Self) -> V {
        // SAFETY: forwarded from the caller.
        unsafe { V::load_ptr(p) }
    }
    #[inline(always)]
    unsafe fn store_ptr<V: Vector>(v: V, p: *mut Self) {
        // SAFETY: forwarded from the caller.
        unsafe { v.store_ptr(p) }
    }
    #[inline(always)]
    fn load<V: Vector>(s: &[Self]) -> V {
        V::load(s)
    }
    #[inline(always)]
    fn store<V: Vector>(v: V, out: &mut [Self], width: usize) {
        v.store(out, width)
    }
}

impl Stored for f32 {
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    unsafe fn load_ptr<V: Vector>(p: *const Self) -> V {
        // SAFETY: forwarded from the caller.
        unsafe { V::load_single_ptr(p) }
    }
    #[inline(always)]
    unsafe fn store_ptr<V: Vector>(v: V, p: *mut Self) {
        // SAFETY: forwarded from the caller.
        unsafe { v.store_single_ptr(p) }
    }
    #[inline(always)]
    fn load<V: Vector>(s: &[Self]) -> V {
        V::load_single(s)
    }
    #[inline(always)]
    fn store<V: Vector>(v: V, out: &mut [Self], width: usize) {
        v.store_single(out, width)
    }
}
