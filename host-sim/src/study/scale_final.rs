//! The time from landing to the first final reading of the firmware's own scale (what the
//! board prints as its `final` line), over seeded drops at each SNR: the `calibration-drop`
//! scene (0.3 s of empty pan, then 138.32 g lands), the scale built from the shipped
//! `firmware/weighing.toml` as both boards build it (`Scale::configured`: onset detection,
//! tare, the 50 ms hold, four `u` within the permissible error). The estimator's own rule
//! (the speed study's "time to final") is a lower bound on it.
//!
//! What it must never do: count a final reading before the landing, or a run never final
//! as final (it counts as not final by the scene's end).

use anyhow::{Context, Result};
use estimator_core::weighing::RawSample;
use rayon::prelude::*;

use crate::montecarlo;
use crate::replay::{self, ConfiguredScale};
use crate::scene::Scene;
use crate::simulated::run_seed;

/// The scene: an empty pan, then the reference mass lands.
pub const SCENE: &str = "calibration-drop";

/// One SNR's runs through the firmware's scale.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaleFinals {
    /// SNR, dB.
    pub snr_db: f64,
    /// Runs.
    pub runs: usize,
    /// Per run, sorted by time: the time from the landing to the first final reading (s)
    /// and its error (g); `(∞, NaN)` for a run never final.
    pub finals: Vec<(f64, f64)>,
}

impl ScaleFinals {
    /// The `q`-quantile of the time to final, s (infinite when fewer runs were final).
    pub fn quantile_s(&self, q: f64) -> f64 {
        montecarlo::finals_quantile(&self.finals, q)
    }

    /// The share of runs final by `time_s` with that first final reading within
    /// `tolerance_g` of the truth.
    pub fn within_by(&self, time_s: f64, tolerance_g: f64) -> f64 {
        montecarlo::finals_within_by(&self.finals, time_s, tolerance_g)
    }

    /// The share of runs whose first final reading lay beyond `tolerance_g`.
    pub fn beyond(&self, tolerance_g: f64) -> f64 {
        montecarlo::finals_beyond(&self.finals, tolerance_g)
    }
}

/// `runs` seeded drops per SNR through the shipped scale; (truth g, rows).
pub fn study(runs: usize, seed: u64, snrs_db: &[f64]) -> Result<(f64, Vec<ScaleFinals>)> {
    let base = Scene::load(SCENE)?;
    let (onset, truth_g, _) = base.studied_step();
    let (weighing, _) = replay::shipped_config()?;
    let rows = snrs_db
        .iter()
        .map(|&snr_db| -> Result<ScaleFinals> {
            let scene = base.with_snr_db(snr_db);
            let counts = replay::calibration(
                scene.chain.counts_per_gram(),
                scene.chain.zero_code(),
                None,
                None,
            );
            ConfiguredScale::configured(&weighing, counts)
                .map_err(|e| anyhow::anyhow!("the shipped configuration is refused: {e}"))?;
            let rate = scene.chain.sample_rate_hz;
            let per_run: Vec<(f64, f64)> = (0..runs)
                .into_par_iter()
                .map(|run| {
                    let mut adc = scene.adc(run_seed(seed, run as u64));
                    // Built above for this configuration: cannot be refused here.
                    let mut scale = Box::new(
                        ConfiguredScale::configured(&weighing, counts).expect("validated"),
                    );
                    for k in 0..scene.samples() {
                        let reading = scale.push(RawSample::read(&mut adc));
                        if k >= onset && reading.is_final {
                            let error = reading.mass_g.map_or(f64::NAN, |m| f64::from(m) - truth_g);
                            return ((k + 1 - onset) as f64 / rate, error);
                        }
                    }
                    (f64::INFINITY, f64::NAN)
                })
                .collect();
            let mut finals = per_run;
            finals.sort_by(|a, b| a.0.total_cmp(&b.0));
            // One per run (`(∞, NaN)`: never final), so the shares are of all runs.
            Ok(ScaleFinals {
                snr_db,
                runs,
                finals,
            })
        })
        .collect::<Result<Vec<_>>>()
        .context("the scale's time to final")?;
    Ok((truth_g, rows))
}
