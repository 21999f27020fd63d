//! Each disturbance and converter option does what its name says, measured on the output.

use estimator_core::sensor::AdcSource;
use host_sim::sensor::{Adc, SensorChain};
use host_sim::{Disturbances, LoadEvent, Script, SimulatedAdc};

fn run(
    chain: SensorChain,
    script: Script<4>,
    disturbances: Disturbances,
    samples: usize,
) -> Vec<f64> {
    let mut adc = SimulatedAdc::new(chain, script, disturbances, 21);
    let (zero, gain) = (chain.zero_code(), chain.counts_per_gram());
    (0..samples)
        .map(|_| (adc.read_analog() - zero) / gain)
        .collect()
}

/// Amplitude of the `hz` component of `y` sampled at 4 kHz (one DFT bin).
fn amplitude(y: &[f64], hz: f64) -> f64 {
    let (mut re, mut im) = (0.0, 0.0);
    for (k, v) in y.iter().enumerate() {
        let phase = 2.0 * std::f64::consts::PI * hz * k as f64 / 4000.0;
        re += v * phase.cos();
        im += v * phase.sin();
    }
    2.0 * (re * re + im * im).sqrt() / y.len() as f64
}

#[test]
fn mains_pickup_is_a_50_hz_line_of_the_set_amplitude() {
    let mut d = Disturbances::none();
    d.mains_amplitude_g = 0.3;
    let y = run(SensorChain::reference(), Script::new(10.0), d, 4000);
    assert!(
        (amplitude(&y, 50.0) - 0.3).abs() < 1e-9,
        "{}",
        amplitude(&y, 50.0)
    );
    assert!(amplitude(&y, 60.0) < 1e-9);
}

#[test]
fn drift_is_linear_in_time() {
    let mut d = Disturbances::none();
    d.drift_g_per_s = 0.01;
    let y = run(SensorChain::reference(), Script::new(10.0), d, 8000);
    assert!((y[4000] - 0.01).abs() < 1e-12 && (y[7999] - 0.01 * 7999.0 / 4000.0).abs() < 1e-12);
}

#[test]
fn creep_approaches_its_fraction_of_the_load_with_its_time_constant() {
    let mut d = Disturbances::none();
    d.creep_fraction = 0.001;
    d.creep_time_constant_s = 0.5;
    let mut script = Script::new(10.0);
    script.push(LoadEvent::step(0.0, 100.0)).unwrap();
    let y = run(SensorChain::reference(), script, d, 16_000);
    // After one time constant: 63.2% of 0.1 g; after 4 s (the cell has settled): all of it.
    let creep_at = |k: usize| y[k] - 100.0;
    assert!(
        (creep_at(15_999) - 0.1).abs() < 0.001,
        "{}",
        creep_at(15_999)
    );
    let plain = run(
        SensorChain::reference(),
        {
            let mut s = Script::new(10.0);
            s.push(LoadEvent::step(0.0, 100.0)).unwrap();
            s
        },
        Disturbances::none(),
        2001,
    );
    let one_tau = y[2000] - plain[2000];
    assert!(
        (one_tau - 0.1 * (1.0 - (-1.0f64).exp())).abs() < 2e-4,
        "{one_tau}"
    );
}

#[test]
fn vibration_is_narrow_band_near_its_centre() {
    let mut d = Disturbances::none();
    d.vibration_rms_g = 0.02;
    d.vibration_hz = 24.0;
    d.vibration_bandwidth_hz = 1.0;
    let y = run(SensorChain::reference(), Script::new(100.0), d, 40_000);
    let rms = (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
    // The force near the resonance (32.6 Hz empty, ζ ≈ 0.023) is amplified, not attenuated.
    assert!(rms > 0.02, "{rms}");
    let near: f64 = [23.0, 24.0, 25.0].iter().map(|f| amplitude(&y, *f)).sum();
    let far: f64 = [10.0, 60.0, 90.0].iter().map(|f| amplitude(&y, *f)).sum();
    assert!(near > 10.0 * far, "near {near} far {far}");
}

#[test]
fn twelve_bit_and_oversampling_scale_the_codes() {
    let mut chain = SensorChain::reference();
    let g16 = chain.counts_per_gram();
    chain.adc = Adc {
        bits: 12,
        reference_v: 2.5,
        oversampling: 4,
    };
    assert!((chain.counts_per_gram() - g16 / 16.0 * 4.0).abs() < 1e-9);
    let mut script = Script::<4>::new(10.0);
    script.push(LoadEvent::step(0.0, 100.0)).unwrap();
    let mut adc = SimulatedAdc::new(chain, script, Disturbances::none(), 1);
    assert_eq!(adc.max_code(), 4 * 4095);
    let mut last = 0;
    for _ in 0..16_000 {
        last = adc.read().unwrap();
    }
    // Settled, noise-free: each of the 4 conversions is within half an LSB of the truth.
    let expected = chain.zero_code() + 100.0 * chain.counts_per_gram();
    assert!(
        (f64::from(last) - expected).abs() <= 2.0 + 1e-6,
        "{last} vs {expected}"
    );
}
