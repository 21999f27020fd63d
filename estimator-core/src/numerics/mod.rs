//! The numerics the estimators stand on: the scalar trait that lets one implementation run
//! in `f32` on the target and `f64` on the host, the square-root-free Givens factor every
//! recursive least-squares solver updates, small dense solves, and the matrix exponential
//! for exact zero-order-hold discretisation.
//!
//! What must never happen here: a division or square root that can turn a finite input
//! into NaN without the caller being able to see it (each solve reports failure as a value).

pub mod expm;
pub(crate) mod factor;
pub(crate) mod real;
pub(crate) mod square;
pub(crate) mod student;
