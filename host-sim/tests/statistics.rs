//! The SNR definition (thesis eq. 4.39) and the Cramér–Rao bound against a Monte Carlo of
//! the known-model maximum-likelihood estimator.

use host_sim::crlb;
use host_sim::sensor::SensorChain;
use host_sim::simulated::{REFERENCE_STEP_G, SNR_WINDOW_SAMPLES};
use host_sim::{white_noise_for_snr, Disturbances, Gaussian, LoadEvent, Script, SimulatedAdc};

/// The reference chain with one step at t = 0 and only white noise of `sigma_g`.
fn step_adc(sigma_g: f64, seed: u64) -> SimulatedAdc<2> {
    let mut script = Script::new(10.0);
    script.push(LoadEvent::step(0.0, REFERENCE_STEP_G)).unwrap();
    SimulatedAdc::new(
        SensorChain::reference(),
        script,
        Disturbances::white(sigma_g),
        seed,
    )
}

#[test]
fn snr_follows_thesis_eq_4_39() {
    // Noise-free and noisy runs of the same scene: the ratio of the clean RMS over the
    // window to the empirical noise RMS, in dB, must be the SNR asked for. 20 runs × 6,000
    // samples: the noise RMS is known to √(1/(2·120000)) = 0.2% = 0.018 dB (1σ); we allow
    // 0.1 dB (> 5σ).
    let chain = SensorChain::reference();
    for snr_db in [30.0, 50.0, 70.0] {
        let sigma_g = white_noise_for_snr(&chain, REFERENCE_STEP_G, snr_db, SNR_WINDOW_SAMPLES);
        let mut clean = step_adc(0.0, 0);
        let clean: Vec<f64> = (0..SNR_WINDOW_SAMPLES)
            .map(|_| clean.read_analog())
            .collect();
        let zero = chain.zero_code();
        let signal_rms =
            (clean.iter().map(|c| (c - zero).powi(2)).sum::<f64>() / clean.len() as f64).sqrt();
        let mut noise_energy = 0.0;
        let mut count = 0.0;
        for run in 0..20 {
            let mut noisy = step_adc(sigma_g, run);
            for c in &clean {
                noise_energy += (noisy.read_analog() - c).powi(2);
                count += 1.0;
            }
        }
        let measured = 20.0 * (signal_rms / (noise_energy / count).sqrt()).log10();
        assert!(
            (measured - snr_db).abs() < 0.1,
            "asked {snr_db} dB, measured {measured} dB"
        );
        // The signal RMS is the step plus the ringing's energy: a decaying oscillation of
        // unit initial amplitude adds about 1/(4ζωT) = 3.5% to the mean square over
        // T = 1.5 s (less the rise), so the RMS lies 1–2% above the step.
        let ratio = signal_rms / chain.counts_per_gram() / REFERENCE_STEP_G;
        assert!(
            (1.005..1.025).contains(&ratio),
            "signal RMS / step = {ratio}"
        );
    }
}

/// Monte Carlo of the known-model ML estimators over `samples` samples from the drop:
/// known tare û = sᵀ(y − b)/(G sᵀs); unknown tare: LS on [G·s, 1]. Returns the variances.
fn ml_variances(samples: usize, runs: usize, sigma_g: f64) -> (f64, f64, Vec<f64>) {
    let chain = SensorChain::reference();
    let gain = chain.counts_per_gram();
    let zero = chain.zero_code();
    let s = crlb::unit_step_response(&chain, REFERENCE_STEP_G, samples);
    let energy: f64 = s.iter().map(|v| v * v).sum();
    let mean_s = s.iter().sum::<f64>() / samples as f64;
    let centred: f64 = s.iter().map(|v| (v - mean_s).powi(2)).sum();
    let (mut known, mut known2, mut unknown, mut unknown2) = (0.0, 0.0, 0.0, 0.0);
    for run in 0..runs {
        let mut adc = step_adc(sigma_g, 1000 + run as u64);
        let y: Vec<f64> = (0..samples).map(|_| adc.read_analog()).collect();
        let estimate_known =
            s.iter().zip(&y).map(|(s, y)| s * (y - zero)).sum::<f64>() / (gain * energy);
        let mean_y = y.iter().sum::<f64>() / samples as f64;
        let estimate_unknown = s
            .iter()
            .zip(&y)
            .map(|(s, y)| (s - mean_s) * (y - mean_y))
            .sum::<f64>()
            / (gain * centred);
        known += estimate_known;
        known2 += estimate_known * estimate_known;
        unknown += estimate_unknown;
        unknown2 += estimate_unknown * estimate_unknown;
    }
    let n = runs as f64;
    let variance = |sum: f64, sum2: f64| (sum2 - sum * sum / n) / (n - 1.0);
    (variance(known, known2), variance(unknown, unknown2), s)
}

#[test]
fn crlb_matches_the_known_model_ml_estimator() {
    // 10,000 runs: the sample variance has relative standard error √(2/10000) = 1.4%, so
    // 10% is ~7σ. The ML estimator of a linear Gaussian model attains the bound, so a
    // wrong bound (a missing G², the wrong sum, the wrong centring) fails by far more.
    let chain = SensorChain::reference();
    let sigma_g = white_noise_for_snr(&chain, REFERENCE_STEP_G, 50.0, SNR_WINDOW_SAMPLES);
    let samples = 400; // 100 ms
    let (var_known, var_unknown, s) = ml_variances(samples, 10_000, sigma_g);
    let gain = chain.counts_per_gram();
    let noise_counts = sigma_g * gain;
    let bound_known = *crlb::white_known_tare(&s, gain, noise_counts * noise_counts)
        .last()
        .unwrap();
    let bound_unknown = *crlb::white_unknown_tare(&s, gain, noise_counts * noise_counts)
        .last()
        .unwrap();
    assert!(
        (var_known / bound_known - 1.0).abs() < 0.1,
        "known tare: MC {var_known:e} vs CRLB {bound_known:e}"
    );
    assert!(
        (var_unknown / bound_unknown - 1.0).abs() < 0.1,
        "unknown tare: MC {var_unknown:e} vs CRLB {bound_unknown:e}"
    );
    // The tare costs information early on: the bounds must differ measurably at 100 ms.
    assert!(
        bound_unknown > 1.5 * bound_known,
        "{bound_unknown:e} vs {bound_known:e}"
    );
}

#[test]
fn coloured_crlb_matches_the_gls_estimator_on_ar1_noise() {
    // AR(1) noise e(k) = φ e(k−1) + w(k), stationary start; the ML (GLS) estimator
    // prewhitens with [1, −φ]. 10,000 runs, same 10% (~7σ) tolerance.
    let chain = SensorChain::reference();
    let samples = 400;
    let s = crlb::unit_step_response(&chain, REFERENCE_STEP_G, samples);
    let (phi, innovation_sd, gain) = (0.9_f64, 1.0, 2.0);
    let stationary_sd = innovation_sd / (1.0 - phi * phi).sqrt();
    let autocovariance: Vec<f64> = (0..samples)
        .map(|lag| stationary_sd.powi(2) * phi.powi(lag as i32))
        .collect();
    let bound = *crlb::coloured_known_tare(&s, gain, &autocovariance)
        .last()
        .unwrap();
    let whiten = |x: &[f64]| -> Vec<f64> {
        let mut w = vec![x[0] * (1.0 - phi * phi).sqrt()];
        w.extend(x.windows(2).map(|p| p[1] - phi * p[0]));
        w
    };
    let sw = whiten(&s);
    let energy: f64 = sw.iter().map(|v| v * v).sum();
    let mut noise = Gaussian::new(99);
    let (mut sum, mut sum2) = (0.0, 0.0);
    let runs = 10_000;
    let u = 3.0;
    for _ in 0..runs {
        let mut e = stationary_sd * noise.standard();
        let y: Vec<f64> = s
            .iter()
            .map(|sk| {
                let value = gain * u * sk + e;
                e = phi * e + innovation_sd * noise.standard();
                value
            })
            .collect();
        let yw = whiten(&y);
        let estimate = sw.iter().zip(&yw).map(|(a, b)| a * b).sum::<f64>() / (gain * energy);
        sum += estimate;
        sum2 += estimate * estimate;
    }
    let n = runs as f64;
    let variance = (sum2 - sum * sum / n) / (n - 1.0);
    assert!(
        (variance / bound - 1.0).abs() < 0.1,
        "MC {variance:e} vs coloured CRLB {bound:e}"
    );
    // Treating this noise as white would misstate the bound by far more than 10%.
    let white = *crlb::white_known_tare(&s, gain, stationary_sd.powi(2))
        .last()
        .unwrap();
    assert!(
        (white / bound - 1.0).abs() > 0.3,
        "white {white:e} vs coloured {bound:e}"
    );
}

#[test]
fn amplifier_noise_autocovariance_matches_simulation() {
    // Only the INA114's noise, empty platform: the empirical variance and lag-10
    // autocovariance of 400,000 output samples against the computed ones. The noise is
    // correlated over ~10 samples (100 Hz at 4 kHz), so these are ~40,000 effective samples
    // and the variance is known to ~√(2/40000) = 0.7%; we allow 5%.
    let chain = SensorChain::reference();
    let mut disturbances = Disturbances::none();
    disturbances.amplifier_noise = true;
    let mut adc = SimulatedAdc::new(chain, Script::<1>::new(1000.0), disturbances, 5);
    let zero = chain.zero_code();
    let gain = chain.counts_per_gram();
    let y: Vec<f64> = (0..400_000)
        .map(|_| (adc.read_analog() - zero) / gain)
        .collect();
    let lag_product = |lag: usize| {
        y.iter()
            .zip(y.iter().skip(lag))
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / (y.len() - lag) as f64
    };
    let computed = crlb::amplifier_autocovariance_g2(&chain, 11);
    for lag in [0, 10] {
        let measured = lag_product(lag);
        assert!(
            (measured / computed[lag] - 1.0).abs() < 0.05,
            "lag {lag}: measured {measured:e} vs computed {:e}",
            computed[lag]
        );
    }
    // The noise is coloured: the lag-10 correlation is far from zero.
    assert!(computed[10] / computed[0] > 0.1, "{:?}", &computed[..11]);
}

#[test]
fn the_tare_record_meters_the_scenes_noise() {
    // `bc` in a study gets σ² from `NoiseMeter` over 1,200 simulated empty-pan samples. At
    // D = 1 one measurement has a relative standard error of √(3/1199) = 5% (noise_meter.rs);
    // the mean of 40 runs is known to 0.8%, so it must match the modelled variance (white +
    // LSB²/12; the amplifier's 0.0068 g adds 0.02%) within 4% (5σ). At D = 16 a run has 74
    // differences (20%): the mean of 40 within 15% (5σ of 3.2%) — block means of the
    // filter-coloured amplifier noise are still negligible here.
    use host_sim::method::measured_tare_variance;
    use host_sim::montecarlo::{tare_record, TARE_SAMPLES};
    let scene = host_sim::scene::Scene::load("reference-step").unwrap();
    let gain = scene.chain.counts_per_gram();
    let white = scene.disturbances.white_noise_g * gain;
    let modelled = white * white + 1.0 / 12.0;
    for (decimation, tolerance) in [(1u16, 0.04), (16, 0.15)] {
        let runs = 40;
        let mean = (0..runs)
            .map(|run| {
                let record = tare_record(&scene, 1, run);
                assert_eq!(record.len(), TARE_SAMPLES);
                measured_tare_variance(&record, decimation).unwrap()
            })
            .sum::<f64>()
            / runs as f64;
        assert!(
            (mean / modelled - 1.0).abs() < tolerance,
            "D = {decimation}: metered {mean:.2} counts², modelled {modelled:.2}"
        );
    }
}
