//! The estimator configurations the on-target check runs, shared by the bare-metal
//! `core_check` binary and the host test that compares against it (`tests::core_check`,
//! through this crate), so the two sides cannot drift apart. Plain constants: nothing here
//! may depend on the target.

/// The stored step response: `f32` little-endian raw samples (zero offset removed),
/// written by `tests::core_check::generate_response_bytes` (see that module).
pub const RESPONSE_FILE: &str = "step_response.f32le";

/// Static gain of the stored response: raw units per gram.
pub const GAIN_PER_G: f32 = 50.0;

/// One estimator configuration: model order, decimation block length, forgetting factor.
#[derive(Clone, Copy, Debug)]
pub struct Case {
    /// Model order `n`.
    pub order: usize,
    /// Block length `D` of the decimator.
    pub decimation: u16,
    /// Forgetting factor λ.
    pub forgetting: f32,
}

const fn case(order: usize, decimation: u16, forgetting: f32) -> Case {
    Case {
        order,
        decimation,
        forgetting,
    }
}

/// n ∈ {2, 5, 7} × D ∈ {1, 8} × λ ∈ {1, 0.99}, all in a `StepEstimator<f32, 12>`.
pub const CASES: [Case; 12] = [
    case(2, 1, 1.0),
    case(2, 1, 0.99),
    case(2, 8, 1.0),
    case(2, 8, 0.99),
    case(5, 1, 1.0),
    case(5, 1, 0.99),
    case(5, 8, 1.0),
    case(5, 8, 0.99),
    case(7, 1, 1.0),
    case(7, 1, 0.99),
    case(7, 8, 1.0),
    case(7, 8, 0.99),
];

/// Capacity of the estimator both sides run.
pub const CAPACITY: usize = 12;
