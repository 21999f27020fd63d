//! The stability map of every estimator: where each method works, and whether, outside that
//! region, the core *flags* the reading (`Invalid(reason)`) or gives a *silent* wrong number.
//!
//! The full Cartesian product (SNR × order × precision × noise × off-calibration × run length)
//! would be ~10⁵ cells; the map runs four slices, each answering one question:
//!
//! - **A, order × SNR**: 10–80 dB × orders 1–40, white noise, f32 and f64, for every
//!   estimator where an order applies: `step` at the firmware's D = 16 and at D = 1,
//!   `covariance`, `iv` and `bc` at D = 16, on the reference scene.
//! - **B, noise type × SNR**: white, vibration near the resonance, 50 Hz mains, every method
//!   at its default configuration (incl. the model bank, the baselines and the ramp).
//! - **C, off-calibration**: the load, and with it the resonance, moved 0.67–1.5× the one at
//!   the 200 g calibration, physically (through the moving mass), for the model-based methods
//!   and, to confirm they do not care, the data-driven ones.
//! - **D, long runs**: up to 10⁷ samples of a steady load at 50 dB with λ = 1, 0.9999, 0.999
//!   (at the decimated rate), f32 and f64, one run per cell.
//!
//! Every Monte Carlo cell is classified at two readouts (100 ms and the end of the 1.5 s
//! window) by what its runs did there ([`Class`]): ok; not yet determined; refused (most runs
//! flagged); over 10× the Cramér–Rao bound; lost positive definiteness (an oracle outside the
//! core: a Cholesky factorisation of the covariance form's Ψ, or a non-positive weight of the
//! factored form); non-finite; diverged (a valid reading 10× the load away). A failure is
//! *silent* when a run failing it still carried a valid reading.
//!
//! The steps, one file each: `probes` (the methods) and `conditions` (the grid of scenes);
//! `oracle` and `run` (one method on one record, then a slice in parallel); `classify` (a
//! cell's class); `long` (slice D); `verdict` (the f32 goal and the failure counts); `csv`,
//! `markdown` and `heatmap` (the reports); `command` (`host-sim study stability`).
//!
//! What this module must never do: compute an estimate itself (every reading comes from the
//! core), judge a method on runs or seeds its rivals did not get (one record per run feeds
//! every method of a slice), or report a cell as valid on the strength of its flagged runs.

mod classify;
mod command;
mod conditions;
mod csv;
mod heatmap;
mod long;
mod markdown;
mod oracle;
mod probes;
mod run;
mod verdict;

pub use classify::{Cell, Class, BOUND_FACTOR, DIVERGED_FACTOR, REASONS};
pub use command::stability_command;
pub use conditions::{
    mass_for_ratio, noise_conditions, noisy_scene, off_calibration_conditions, order_conditions,
    readout_indices, resonance_ratio, vibration_gain, Condition, Noise, Slice, CALIBRATION_G,
    OFF_CALIBRATION_SNRS_DB, ORDERS, ORDER_MAP_DECIMATION, READOUTS_S, RESONANCE_RATIOS, SNRS_DB,
};
pub use csv::write_csv;
pub use heatmap::{long_chart, order_heat_map, probe_heat_map, HeatMap, Panel};
pub use long::{
    long_probes, run_long_slice, steady_bound_g, Bin, LongResult, LongRun, BINS_PER_DECADE,
    FIRST_DECADE, LONG_DECIMATIONS, LONG_FORGETTING, LONG_LOAD_G, LONG_SAMPLES,
};
pub use markdown::write_markdown;
pub use probes::{default_probes, order_probes, Probe};
pub use run::{run_slice, Outcome, RunOutcome, SliceResult};
pub use verdict::{
    f32_goal, failure_summary, long_f32_goal, F32Failure, FamilyFailures, F32_TOLERANCE,
};
