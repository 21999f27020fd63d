// Generated from firmware/weighing.toml by host_sim::calibrate::firmware_constants; do not edit.
/// The weighing configuration the firmware runs (written by `host-sim calibrate`).
pub const WEIGHING: WeighingConfig = WeighingConfig {
    method: WeighingMethod::Step { order: 5, decimation: 24, forgetting: 1.0 },
    counts_per_gram: 73.2559336479721,
    zero_counts: 16764.60532150776,
    noise_variance_counts2: 987.1805578975175,
    raw_noise_variance_counts2: 1048.4273119542636,
    onset: OnsetConfig { min_empty_samples: 400, drift_sigma: 1.0, threshold_sigma: 12.0, guard_samples: 8, min_step_sigma: 10.0, min_noise_rms: 0.5, rail_low: 0.0, rail_high: 65535.0 },
    detection_lag_samples: 10.385,
    model: LoadCellModel { natural_frequency_hz: 25.000156487736767, damping_ratio: 0.0300060250982748, filter_order: 3, filter_cutoff_hz: 100.0, counts_per_gram: 73.2559336479721, sample_rate_hz: 4000.0 },
    identified_counts_per_gram: 73.2559336479721,
    calibration_mass_g: 138.32,
    readout_s: 0.1,
    target_relative: 0.0005,
    prediction: Prediction { runs: 400, planned_runs: 400, valid_runs: 400, within_target_runs: 390, detection_failures: 0, bias_g: 0.0006505966186591649, rms_g: 0.031573179536262284, p95_g: 0.06150024414063182, p95_upper_g: 0.06781738281250682 },
    recorded_drops: 3,
    recorded_worst_error_g: 0.04032104492188182,
    loads: LoadCoverage {
        min_g: 138.32,
        max_g: 341.72073019803156,
        loads: 4,
        platform_mass_g: None,
        scores: [
            Some(LoadScore { scene: LoadScene { mass_g: 138.32, frequency_ratio: 1.0 }, noise_floor_g: 0.02607519795340683, prediction: Prediction { runs: 400, planned_runs: 400, valid_runs: 400, within_target_runs: 390, detection_failures: 0, bias_g: 0.0006505966186591649, rms_g: 0.031573179536262284, p95_g: 0.06150024414063182, p95_upper_g: 0.06781738281250682 } }),
            Some(LoadScore { scene: LoadScene { mass_g: 186.98801102263184, frequency_ratio: 0.8600735839838766 }, noise_floor_g: 0.02580659598364207, prediction: Prediction { runs: 400, planned_runs: 400, valid_runs: 400, within_target_runs: 399, detection_failures: 0, bias_g: 9.27295043925369e-5, rms_g: 0.032522708376202136, p95_g: 0.05923018830566207, p95_upper_g: 0.06476912873534957 } }),
            Some(LoadScore { scene: LoadScene { mass_g: 186.98801102263184, frequency_ratio: 1.0 }, noise_floor_g: 0.026075197953406803, prediction: Prediction { runs: 400, planned_runs: 400, valid_runs: 400, within_target_runs: 400, detection_failures: 0, bias_g: -0.0014220104858418381, rms_g: 0.028733958555435108, p95_g: 0.05658402067871293, p95_upper_g: 0.06344161408691207 } }),
            Some(LoadScore { scene: LoadScene { mass_g: 252.77990360179214, frequency_ratio: 0.7397265698668704 }, noise_floor_g: 0.024746846804939514, prediction: Prediction { runs: 400, planned_runs: 400, valid_runs: 400, within_target_runs: 400, detection_failures: 0, bias_g: -0.00407691874770876, rms_g: 0.03420494292612301, p95_g: 0.06432742991714235, p95_upper_g: 0.07235355296401735 } }),
            Some(LoadScore { scene: LoadScene { mass_g: 252.77990360179214, frequency_ratio: 1.0 }, noise_floor_g: 0.026075197953406824, prediction: Prediction { runs: 400, planned_runs: 400, valid_runs: 400, within_target_runs: 400, detection_failures: 0, bias_g: 0.0015493019554162402, rms_g: 0.035422458137082266, p95_g: 0.07042293629379515, p95_upper_g: 0.07684688648910765 } }),
            Some(LoadScore { scene: LoadScene { mass_g: 341.7207301980316, frequency_ratio: 0.6362192821134985 }, noise_floor_g: 0.025031603432063974, prediction: Prediction { runs: 400, planned_runs: 400, valid_runs: 400, within_target_runs: 400, detection_failures: 0, bias_g: -0.005205753451539294, rms_g: 0.03595443046566233, p95_g: 0.06707419217224242, p95_upper_g: 0.07772482693786742 } }),
            Some(LoadScore { scene: LoadScene { mass_g: 341.7207301980316, frequency_ratio: 1.0 }, noise_floor_g: 0.026075197953406806, prediction: Prediction { runs: 400, planned_runs: 400, valid_runs: 400, within_target_runs: 400, detection_failures: 0, bias_g: -0.003307178622437732, rms_g: 0.03333875312156885, p95_g: 0.06130636990661742, p95_upper_g: 0.06869162381286742 } }),
            None,
            None,
            None,
            None,
            None,
            None,
            None,
            None,
            None,
            None,
        ],
    },
    capacity_g: 600.0,
    scale_interval_g: 0.1,
    final_target_g: 0.05,
};
/// Largest model order the estimator holds: the configured one or the largest a console may upload (1 for the bank).
pub const ORDER_CAPACITY: usize = 8;
/// States of the identified model (the bank's candidates): 2 + the filter's order.
pub const MODEL_STATES: usize = 5;
/// Candidates of the model bank (0 for the data-driven methods: no bank code in the image).
pub const BANK_CANDIDATES: usize = 0;
