//! The floating-point types the estimators run in.
//!
//! The Cortex-M4F has a single-precision FPU, so firmware runs `f32`; the host also runs
//! `f64` as the reference the `f32` path is checked against. Only what the estimators need
//! is here, so that nothing in the core depends on `std`.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real number type the estimators are generic over: `f32` or `f64`.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    /// Additive identity.
    const ZERO: Self;
    /// Multiplicative identity.
    const ONE: Self;
    /// Machine epsilon of the type.
    const EPSILON: Self;
    /// Name used in reports ("f32" or "f64").
    const NAME: &'static str;

    /// Nearest value of this type.
    fn from_f64(value: f64) -> Self;
    /// Exact widening to `f64`.
    fn to_f64(self) -> f64;
    /// Nearest value of this type (exact for |value| ≤ 2^24 in `f32`).
    fn from_i32(value: i32) -> Self;
    /// Nearest value of this type.
    fn from_u32(value: u32) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Neither NaN nor infinite.
    fn is_finite(self) -> bool;
    /// Square root (libm; not on the estimator's hot path).
    fn sqrt(self) -> Self;
}

/// `Real` for a primitive float, with its `libm` square root.
macro_rules! impl_real {
    ($float:ident, $sqrt:path) => {
        impl Real for $float {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const EPSILON: Self = $float::EPSILON;
            const NAME: &'static str = stringify!($float);

            #[inline]
            fn from_f64(value: f64) -> Self {
                value as $float
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn from_i32(value: i32) -> Self {
                value as $float
            }
            #[inline]
            fn from_u32(value: u32) -> Self {
                value as $float
            }
            #[inline]
            fn abs(self) -> Self {
                $float::abs(self)
            }
            #[inline]
            fn is_finite(self) -> bool {
                $float::is_finite(self)
            }
            #[inline]
            fn sqrt(self) -> Self {
                $sqrt(self)
            }
        }
    };
}

impl_real!(f32, libm::sqrtf);
impl_real!(f64, libm::sqrt);
