//! Writing the file: one function per table, in the order of the file, each with the
//! comments that say what was measured and how (the provenance, when calibration wrote it).

use std::fmt::Write as _;

use estimator_core::tuning::{CandidateScore, Tuned};
use estimator_core::weighing::{LoadScore, Prediction, WeighingConfig};

use super::{
    interpolation_name, kind_name, method_keys, model_keys, onset_keys, precision_name, FORMAT,
    KINDS,
};
use crate::calibrate::{method_spec, percent, scene_name, Outcome};
use crate::montecarlo::Precision;

// Writing to a String cannot fail: every `writeln!` below is `let _ =`.

/// The configuration as TOML, with comments that say what was measured. `command` is the
/// command line that produced it, `names` the drop files.
pub fn to_toml(outcome: &Outcome, names: &[String], command: &str) -> String {
    let calibrated = &outcome.calibrated;
    write_toml(
        &calibrated.config,
        outcome.precision,
        Some(&Provenance {
            calibrated,
            scores: &outcome.scores,
            names,
            command,
            elapsed_s: outcome.elapsed_s,
        }),
    )
}

/// The configuration as TOML without the provenance comments (for tests and round trips).
pub fn config_toml(config: &WeighingConfig, precision: Precision) -> String {
    write_toml(config, precision, None)
}

/// How calibration arrived at the configuration: the comments only it can write.
struct Provenance<'a> {
    calibrated: &'a Tuned,
    scores: &'a [CandidateScore],
    names: &'a [String],
    command: &'a str,
    elapsed_s: f64,
}

fn write_toml(
    config: &WeighingConfig,
    precision: Precision,
    provenance: Option<&Provenance<'_>>,
) -> String {
    let mut w = String::new();
    header(&mut w, config, provenance);
    method(&mut w, config, precision, provenance);
    scale(&mut w, config);
    onset(&mut w, config);
    model(&mut w, config, provenance);
    target(&mut w, config);
    measured(&mut w, config, provenance);
    range(&mut w, config);
    for score in config.loads.scores.iter().flatten() {
        load(&mut w, config, score);
    }
    w
}

/// Comment lines.
fn comments(w: &mut String, lines: &[&str]) {
    for line in lines {
        let _ = writeln!(w, "# {line}");
    }
}

/// A float as TOML writes it: shortest round-trip form, `inf`/`-inf`/`nan` spelled out.
fn number(value: f64) -> String {
    if value.is_nan() {
        "nan".into()
    } else if value.is_infinite() {
        if value > 0.0 { "inf" } else { "-inf" }.into()
    } else if value == value.trunc() && value.abs() < 1e15 {
        // `1` would read back as an integer, which a float field refuses.
        format!("{value:.1}")
    } else {
        format!("{value}")
    }
}

/// The file's opening comments and its `format`.
fn header(w: &mut String, config: &WeighingConfig, provenance: Option<&Provenance<'_>>) {
    let _ = writeln!(
        w,
        "# Weighing configuration, written by `host-sim calibrate` (estimator-core tuning::tune)."
    );
    if let Some(prov) = provenance {
        let _ = writeln!(w, "# Command: {}", prov.command);
        let _ = writeln!(
            w,
            "# From {} drops of {} g: {}. Calibration took {:.2} s ({} candidates scored).",
            prov.names.len(),
            config.calibration_mass_g,
            prov.names.join(", "),
            prov.elapsed_s,
            prov.calibrated.evaluated
        );
    }
    let _ = writeln!(w, "format = {FORMAT}\n");
}

/// `[method]`.
fn method(
    w: &mut String,
    config: &WeighingConfig,
    precision: Precision,
    provenance: Option<&Provenance<'_>>,
) {
    let _ = writeln!(w, "[method]");
    comments(
        w,
        &[
            "The smallest candidate (model order n first, then the solver: least squares, with",
            "forgetting, bias-compensated, instrumental variables; then the largest D; the model bank",
            "last) whose 95th-percentile |error| at the readout is within the target with 95%",
            "confidence over the Monte Carlo below, and that is within the target on every recorded drop.",
        ],
    );
    if let Some(prov) = provenance {
        let chosen = prov.calibrated.chosen.index;
        let smaller = prov.scores.iter().filter(|s| s.index < chosen).count();
        if smaller > 0 {
            let _ = writeln!(
                w,
                "# {smaller} smaller candidates did not meet the target (the run log lists each)."
            );
        }
    }
    let _ = writeln!(
        w,
        "kind = \"{}\"   # one of {KINDS}",
        kind_name(&config.method)
    );
    let _ = writeln!(
        w,
        "precision = \"{}\"   # the arithmetic it was scored in",
        precision_name(precision)
    );
    let _ = writeln!(
        w,
        "spec = \"{}\"   # the same as host-sim's --method spec",
        method_spec(config, precision)
    );
    let quoted = |interpolation| format!("\"{}\"", interpolation_name(interpolation));
    for (key, value) in method_keys(&config.method, number, quoted) {
        let _ = writeln!(w, "{key} = {value}");
    }
}

/// `[scale]`.
fn scale(w: &mut String, config: &WeighingConfig) {
    let _ = writeln!(w, "\n[scale]");
    let derived = (config.counts_per_gram - config.identified_counts_per_gram).abs()
        <= 1e-12 * config.counts_per_gram.abs();
    if derived {
        let _ = writeln!(
            w,
            "# Gain derived from the drops: the identified model's fitted step over the known mass"
        );
        let _ = writeln!(
            w,
            "# (the level the fitted transient settles to), mean over the drops."
        );
    } else {
        let _ = writeln!(
            w,
            "# Gain given on the command line; the drops showed {} counts/g ({:+.4}%).",
            config.identified_counts_per_gram,
            (config.identified_counts_per_gram / config.counts_per_gram - 1.0) * 100.0
        );
    }
    let _ = writeln!(w, "counts_per_gram = {}", number(config.counts_per_gram));
    let _ = writeln!(
        w,
        "identified_counts_per_gram = {}",
        number(config.identified_counts_per_gram)
    );
    let _ = writeln!(
        w,
        "# Mean of the empty-pan stretches before the onsets (re-tare before weighing)."
    );
    let _ = writeln!(w, "zero_counts = {}", number(config.zero_counts));
    let noise = [
        (
            "White noise of one sample on the empty stretches (NoiseMeter), at the method's D",
            "noise_variance_counts2",
            config.noise_variance_counts2,
        ),
        (
            "The same at D = 1",
            "raw_noise_variance_counts2",
            config.raw_noise_variance_counts2,
        ),
    ];
    for (what, key, variance) in noise {
        let _ = writeln!(
            w,
            "# {what}: sigma = {:.3} counts = {:.4} g.\n{key} = {}",
            variance.sqrt(),
            variance.sqrt() / config.counts_per_gram,
            number(variance)
        );
    }
    let _ = writeln!(
        w,
        "# Capacity Max and scale interval e (OIML R 76): overload above Max + 9 e; zero\n\
         # tracking and the block-mean change test are set in e (estimator-core ScaleConfig)."
    );
    let _ = writeln!(w, "capacity_g = {}", number(config.capacity_g));
    let _ = writeln!(w, "scale_interval_g = {}", number(config.scale_interval_g));
    let _ = writeln!(
        w,
        "# A reading is final once twice its standard uncertainty, its noise level taken at\n\
         # the upper 95 % confidence bound, is at or below this (g; or final_target_e in\n\
         # scale intervals). Default 0.5 e: OIML R 76's smallest MPE."
    );
    let _ = writeln!(w, "final_target_g = {}", number(config.final_target_g));
}

/// `[onset]`.
fn onset(w: &mut String, config: &WeighingConfig) {
    let _ = writeln!(w, "\n[onset]");
    comments(
        w,
        &[
            "How the scale must find the landing (estimator-core tuning::onset): two-sided CUSUM on",
            "the deviation from the zero in noise standard deviations, backed off to the start of the",
            "excursion. The method was scored started there AND at the landing itself: start it",
            "anywhere in between (not before the landing). A code at or beyond a rail is saturated.",
        ],
    );
    for (key, value) in onset_keys(&config.onset, number) {
        let _ = writeln!(w, "{key} = {value}");
    }
}

/// `[model]`.
fn model(w: &mut String, config: &WeighingConfig, provenance: Option<&Provenance<'_>>) {
    let _ = writeln!(w, "\n[model]");
    comments(
        w,
        &[
            "Identified from the drops (estimator-core identify): the mechanical mode with the load on,",
            "in series with the known Butterworth low-pass.",
        ],
    );
    if let Some(prov) = provenance {
        let i = &prov.calibrated.identified;
        let _ = writeln!(
            w,
            "# Fit: {} model evaluations, residual {:.3} counts per raw sample.",
            i.evaluations, i.noise_rms
        );
    }
    for (key, value) in model_keys(&config.model, number) {
        let _ = writeln!(w, "{key} = {value}");
    }
}

/// `[target]`.
fn target(w: &mut String, config: &WeighingConfig) {
    let mass = config.calibration_mass_g;
    let _ = writeln!(w, "\n[target]");
    let _ = writeln!(
        w,
        "# {} of {} g = {:.4} g, {} ms after the mass lands.",
        percent(config.target_relative),
        mass,
        config.target_relative * mass,
        config.readout_s * 1e3
    );
    let _ = writeln!(
        w,
        "calibration_mass_g = {}\nreadout_s = {}\ntarget_relative = {}",
        number(mass),
        number(config.readout_s),
        number(config.target_relative)
    );
}

/// `[measured]`.
fn measured(w: &mut String, config: &WeighingConfig, provenance: Option<&Provenance<'_>>) {
    let mass = config.calibration_mass_g;
    let p = &config.prediction;
    let _ = writeln!(w, "\n[measured]");
    let _ = writeln!(
        w,
        "# Monte Carlo: {} synthetic drops of the identified model at the gain the drops showed,",
        p.planned_runs
    );
    let _ = writeln!(w, "# white noise at the upper confidence value of the measured variance, each through the same");
    let _ = writeln!(
        w,
        "# onset detection and tare, read {} ms after the landing.",
        config.readout_s * 1e3
    );
    if let Some(prov) = provenance {
        let c = prov.calibrated;
        let _ = writeln!(
            w,
            "# Noise used: sigma = {:.3} counts (measured {:.3}, relative standard error of the variance {:.1}%); {} empty samples before each drop.",
            c.monte_carlo_noise_variance_counts2.sqrt(),
            config.raw_noise_variance_counts2.sqrt(),
            c.noise_relative_standard_error * 100.0,
            c.synthetic_empty_samples
        );
    }
    let _ = writeln!(
        w,
        "# Predicted at the readout: RMS {:.4} g ({}), 95th percentile {:.4} g ({}), its 95% upper bound {:.4} g ({}).",
        p.rms_g,
        percent(p.rms_g / mass),
        p.p95_g,
        percent(p.p95_g / mass),
        p.p95_upper_g,
        percent(p.p95_upper_g / mass)
    );
    prediction_keys(w, p);
    if let Some(prov) = provenance {
        if let Some(check) = &prov.calibrated.chosen.recorded {
            let each: Vec<String> = prov
                .names
                .iter()
                .zip(check.errors_g.iter())
                .map(|(name, e)| format!("{name} {e:+.4} g"))
                .collect();
            let _ = writeln!(
                w,
                "# Confirmed on the recorded drops (the larger error of the two starts): {}.",
                each.join(", ")
            );
        }
    }
    let _ = writeln!(
        w,
        "# Mean lag of the detected onset behind the landing in the synthetic drops, samples."
    );
    let _ = writeln!(
        w,
        "detection_lag_samples = {}\nrecorded_drops = {}\nrecorded_worst_error_g = {}",
        number(config.detection_lag_samples),
        config.recorded_drops,
        number(config.recorded_worst_error_g)
    );
}

/// The keys of a prediction, in `[measured]` and each `[[load]]`.
fn prediction_keys(w: &mut String, p: &Prediction) {
    let _ = writeln!(w, "runs = {}\nplanned_runs = {}\nvalid_runs = {}\nwithin_target_runs = {}\ndetection_failures = {}",
        p.runs, p.planned_runs, p.valid_runs, p.within_target_runs, p.detection_failures);
    let _ = writeln!(
        w,
        "bias_g = {}\nrms_g = {}\np95_g = {}\np95_upper_g = {}",
        number(p.bias_g),
        number(p.rms_g),
        number(p.p95_g),
        number(p.p95_upper_g)
    );
}

/// `[range]`.
fn range(w: &mut String, config: &WeighingConfig) {
    let loads = &config.loads;
    let _ = writeln!(w, "\n[range]");
    let _ = writeln!(
        w,
        "# The target holds, relative to the load ({} of it), at every scene below: the calibration",
        percent(config.target_relative)
    );
    comments(
        w,
        &[
            "mass and `loads` loads spaced geometrically over [min_g, max_g], each with its own synthetic",
            "drops of the identified model moved to that load by the physical law (stiffness and damping",
        ],
    );
    match loads.platform_mass_g {
        Some(platform) => {
            let _ = writeln!(w, "# fixed) with the platform's moving mass {platform} g.");
        }
        None => {
            let _ = writeln!(w, "# fixed). The platform's moving mass is unknown: each load was scored at both ends of what");
            let _ = writeln!(w, "# physics allows, as calibrated (mass -> infinity) and sqrt(calibration mass / load) times");
            let _ = writeln!(
                w,
                "# faster (mass -> 0). `platform_mass_g` absent: unknown."
            );
        }
    }
    let _ = writeln!(
        w,
        "min_g = {}\nmax_g = {}\nloads = {}",
        number(loads.min_g),
        number(loads.max_g),
        loads.loads
    );
    if let Some(platform) = loads.platform_mass_g {
        let _ = writeln!(w, "platform_mass_g = {}", number(platform));
    }
}

/// One `[[load]]`: a scored scene of the range.
fn load(w: &mut String, config: &WeighingConfig, score: &LoadScore) {
    let p = &score.prediction;
    let mass = score.scene.mass_g;
    let _ = writeln!(w, "\n[[load]]");
    let _ = writeln!(
        w,
        "# {}: RMS {:.4} g ({}), 95th percentile {:.4} g ({}), bound {:.4} g ({}) <= {:.4} g; noise floor {:.4} g ({}).",
        scene_name(&score.scene),
        p.rms_g,
        percent(p.rms_g / mass),
        p.p95_g,
        percent(p.p95_g / mass),
        p.p95_upper_g,
        percent(p.p95_upper_g / mass),
        config.target_relative * mass,
        score.noise_floor_g,
        percent(score.noise_floor_g / mass)
    );
    let _ = writeln!(
        w,
        "mass_g = {}\nfrequency_ratio = {}\nnoise_floor_g = {}",
        number(mass),
        number(score.scene.frequency_ratio),
        number(score.noise_floor_g)
    );
    prediction_keys(w, p);
}
