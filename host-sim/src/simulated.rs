//! The sensor model playing a scripted scene, as an [`AdcSource`]: the QEMU board's ADC and
//! the simulator's data source. Fixed size, allocation-free, panic-free, seeded: the same
//! seed must always give the same samples, on the host and on the board.

use estimator_core::sensor::{AdcError, AdcSource};
use rand_core::{RngCore, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::sensor::{DiscreteSensor, SensorChain, STATES};

/// One change of the load on the platform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoadEvent {
    /// When the change starts, s from the start of the scene.
    pub time_s: f64,
    /// The load after the change, g.
    pub mass_g: f64,
    /// 0 for a step (an item dropped or lifted); otherwise the load moves linearly from the
    /// previous load to `mass_g` over this many seconds (an item sliding on, a conveyor).
    pub ramp_s: f64,
}

impl LoadEvent {
    /// A step to `mass_g` at `time_s`.
    pub const fn step(time_s: f64, mass_g: f64) -> Self {
        Self {
            time_s,
            mass_g,
            ramp_s: 0.0,
        }
    }
}

/// Standard gravity, m/s².
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// A load placed by hand: from `time_s` the load rises over `rise_s` to `mass_g` plus
/// `overshoot` (a fraction) of the change from `previous_g`, then settles back to `mass_g`
/// over `bounce_s` (the hand lets go).
pub fn placed_by_hand(
    time_s: f64,
    previous_g: f64,
    mass_g: f64,
    rise_s: f64,
    overshoot: f64,
    bounce_s: f64,
) -> [LoadEvent; 2] {
    let peak = mass_g + overshoot * (mass_g - previous_g);
    [
        LoadEvent {
            time_s,
            mass_g: peak,
            ramp_s: rise_s,
        },
        LoadEvent {
            time_s: time_s + rise_s,
            mass_g,
            ramp_s: bounce_s,
        },
    ]
}

/// An item dropped from `height_m` onto a pan holding `previous_g`, so that it then holds
/// `mass_g`: the impact is a force pulse of `contact_s` carrying the item's momentum
/// m·√(2gh) (an extra load of m·√(2gh)/(g·contact_s)), then the load stays.
pub fn dropped_from_height(
    time_s: f64,
    previous_g: f64,
    mass_g: f64,
    height_m: f64,
    contact_s: f64,
) -> [LoadEvent; 2] {
    let item_g = mass_g - previous_g;
    let speed = libm::sqrt(2.0 * STANDARD_GRAVITY * height_m.max(0.0));
    let impact_g = item_g * speed / (STANDARD_GRAVITY * contact_s);
    [
        LoadEvent::step(time_s, mass_g + impact_g),
        LoadEvent::step(time_s + contact_s, mass_g),
    ]
}

/// Why a script refused an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScriptError {
    /// The script holds no more events.
    Full,
    /// Events must come in time order and within the scene.
    OutOfOrder,
    /// A time, mass or ramp length was NaN, infinite or negative.
    NotFinite,
}

/// A fixed-size list of load events, in time order, and the end of the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Script<const E: usize> {
    events: [LoadEvent; E],
    len: usize,
    end_s: f64,
}

impl<const E: usize> Script<E> {
    /// An empty platform for `end_s` seconds.
    pub fn new(end_s: f64) -> Self {
        Self {
            events: [LoadEvent::step(0.0, 0.0); E],
            len: 0,
            end_s: if end_s.is_finite() && end_s > 0.0 {
                end_s
            } else {
                0.0
            },
        }
    }

    /// Add the next event.
    pub fn push(&mut self, event: LoadEvent) -> Result<(), ScriptError> {
        let finite =
            event.time_s.is_finite() && event.mass_g.is_finite() && event.ramp_s.is_finite();
        if !finite || event.time_s < 0.0 || event.ramp_s < 0.0 {
            return Err(ScriptError::NotFinite);
        }
        let previous_end = match self.events().last() {
            Some(last) => last.time_s + last.ramp_s,
            None => 0.0,
        };
        if event.time_s < previous_end || event.time_s > self.end_s {
            return Err(ScriptError::OutOfOrder);
        }
        let slot = self.events.get_mut(self.len).ok_or(ScriptError::Full)?;
        *slot = event;
        self.len += 1;
        Ok(())
    }

    /// The events so far.
    pub fn events(&self) -> &[LoadEvent] {
        self.events.get(..self.len).unwrap_or(&[])
    }

    /// The end of the scene, s.
    pub fn end_s(&self) -> f64 {
        self.end_s
    }

    /// The load held over the conversion interval `[k·h, (k+1)·h)`: steps take effect from
    /// the first conversion at or after their time; ramps are sampled mid-interval.
    pub fn load_over(&self, conversion: u64, period_s: f64) -> f64 {
        let mut load = 0.0;
        for event in self.events() {
            let onset = libm::ceil(event.time_s / period_s - 1e-9);
            let since = conversion as f64 - onset;
            if since < 0.0 {
                break;
            }
            if event.ramp_s > 0.0 {
                let fraction = ((since + 0.5) * period_s / event.ramp_s).min(1.0);
                load += (event.mass_g - load) * fraction;
            } else {
                load = event.mass_g;
            }
        }
        load
    }
}

/// Everything that is not the load: noises and slow errors. All levels are equivalent
/// loads in grams (so a scene reads in the unit of the result).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disturbances {
    /// Standard deviation of white measurement noise at the ADC input, g (see
    /// [`white_noise_for_snr`] for the thesis's SNR, eq. 4.39).
    pub white_noise_g: f64,
    /// Add the INA114's input-referred noise (through the anti-alias filter).
    pub amplifier_noise: bool,
    /// RMS of a narrow-band force disturbance (floor vibration), g.
    pub vibration_rms_g: f64,
    /// Centre frequency of the vibration, Hz.
    pub vibration_hz: f64,
    /// Bandwidth of the vibration, Hz.
    pub vibration_bandwidth_hz: f64,
    /// Amplitude of mains pickup at the ADC input, g.
    pub mains_amplitude_g: f64,
    /// Mains frequency, Hz.
    pub mains_hz: f64,
    /// Zero drift, g/s (thermal drift of the offset).
    pub drift_g_per_s: f64,
    /// Creep: the output approaches `(1 + creep_fraction)·load` with this fraction...
    pub creep_fraction: f64,
    /// ...and this time constant, s.
    pub creep_time_constant_s: f64,
}

impl Disturbances {
    /// No noise at all.
    pub const fn none() -> Self {
        Self {
            white_noise_g: 0.0,
            amplifier_noise: false,
            vibration_rms_g: 0.0,
            vibration_hz: 24.0,
            vibration_bandwidth_hz: 1.0,
            mains_amplitude_g: 0.0,
            mains_hz: 50.0,
            drift_g_per_s: 0.0,
            creep_fraction: 0.0,
            creep_time_constant_s: 60.0,
        }
    }

    /// Only white noise of this standard deviation, g.
    pub const fn white(white_noise_g: f64) -> Self {
        let mut disturbances = Self::none();
        disturbances.white_noise_g = white_noise_g;
        disturbances
    }
}

/// The noise-free response of `chain` to a step of `step_g` from an empty platform, sample
/// by sample (the first sample is taken at the instant of the drop, so it is 0).
pub struct StepResponse {
    chain: SensorChain,
    model: DiscreteSensor,
    state: [f64; STATES],
    step_g: f64,
}

impl StepResponse {
    /// Start at the drop.
    pub fn new(chain: &SensorChain, step_g: f64) -> Self {
        // Output samples at the sample rate, whatever the oversampling.
        let period = 1.0 / chain.sample_rate_hz;
        Self {
            chain: *chain,
            model: chain.discretise_over(step_g, period),
            state: [0.0; STATES],
            step_g,
        }
    }

    /// The chain this response belongs to.
    pub fn chain(&self) -> &SensorChain {
        &self.chain
    }
}

impl Iterator for StepResponse {
    type Item = f64;
    fn next(&mut self) -> Option<f64> {
        Some(self.model.step(&mut self.state, [self.step_g, 0.0, 0.0]))
    }
}

/// The white-noise standard deviation (g) that gives `snr_db` by the thesis's definition
/// (eq. 4.39): SNR = 20·log10(rms(y)/σ), with `y` the noise-free response to the step of
/// `step_g`, taken over the `window_samples` samples from the drop.
pub fn white_noise_for_snr(
    chain: &SensorChain,
    step_g: f64,
    snr_db: f64,
    window_samples: usize,
) -> f64 {
    let mut sum_squares = 0.0;
    for value in StepResponse::new(chain, step_g).take(window_samples.max(1)) {
        sum_squares += value * value;
    }
    let rms = libm::sqrt(sum_squares / window_samples.max(1) as f64);
    rms / libm::pow(10.0, snr_db / 20.0)
}

/// A seeded normal-variate source (xoshiro256++ and the Box–Muller transform).
#[derive(Clone, Debug)]
pub struct Gaussian {
    rng: Xoshiro256PlusPlus,
    spare: Option<f64>,
}

impl Gaussian {
    /// A stream from a 64-bit seed.
    pub fn new(seed: u64) -> Self {
        Self {
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
            spare: None,
        }
    }

    /// Uniform in (0, 1].
    pub fn uniform(&mut self) -> f64 {
        ((self.rng.next_u64() >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// A standard normal variate.
    pub fn standard(&mut self) -> f64 {
        if let Some(spare) = self.spare.take() {
            return spare;
        }
        let radius = libm::sqrt(-2.0 * libm::log(self.uniform()));
        let angle = 2.0 * core::f64::consts::PI * self.uniform();
        self.spare = Some(radius * libm::sin(angle));
        radius * libm::cos(angle)
    }
}

/// The seed of run `run` of a study seeded with `seed`: independent of the order the runs
/// are computed in, so a study gives the same numbers on any number of threads.
pub fn run_seed(seed: u64, run: u64) -> u64 {
    // Two rounds of SplitMix64's finaliser over (seed, run).
    fn mix(mut z: u64) -> u64 {
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    mix(mix(seed.wrapping_add(0x9e37_79b9_7f4a_7c15)) ^ run.wrapping_mul(0x9e37_79b9_7f4a_7c15))
}

/// The narrow-band vibration: a second-order resonator driven by white noise.
#[derive(Clone, Copy, Debug)]
struct Resonator {
    feedback: [f64; 2],
    drive: f64,
    past: [f64; 2],
}

impl Resonator {
    fn new(
        rms: f64,
        centre_hz: f64,
        bandwidth_hz: f64,
        rate_hz: f64,
        noise: &mut Gaussian,
    ) -> Self {
        let radius = libm::exp(-core::f64::consts::PI * bandwidth_hz.max(1e-3) / rate_hz);
        let angle = 2.0 * core::f64::consts::PI * centre_hz / rate_hz;
        let a1 = 2.0 * radius * libm::cos(angle);
        let a2 = -radius * radius;
        // Stationary variance of an AR(2): σ_w²(1 − a2)/((1 + a2)((1 − a2)² − a1²)).
        let gain = (1.0 + a2) * ((1.0 - a2) * (1.0 - a2) - a1 * a1) / (1.0 - a2);
        let drive = rms * libm::sqrt(gain.max(0.0));
        Self {
            feedback: [a1, a2],
            drive,
            // Start near the stationary level so a scene need not wait for it to build up.
            past: [rms * noise.standard(), rms * noise.standard()],
        }
    }

    fn next(&mut self, noise: &mut Gaussian) -> f64 {
        let value = self.feedback[0] * self.past[0]
            + self.feedback[1] * self.past[1]
            + self.drive * noise.standard();
        self.past = [value, self.past[0]];
        value
    }
}

/// The sensor chain playing a script, one ADC code per [`AdcSource::read`].
///
/// `E` is the capacity of the script. Reads go on after the end of the script with the last
/// load (see [`SimulatedAdc::is_finished`]).
#[derive(Clone, Debug)]
pub struct SimulatedAdc<const E: usize> {
    chain: SensorChain,
    script: Script<E>,
    disturbances: Disturbances,
    model: DiscreteSensor,
    state: [f64; STATES],
    noise: Gaussian,
    vibration: Resonator,
    mains_phase: f64,
    creep_g: f64,
    conversions: u64,
    load_g: f64,
}

/// The script of [`SimulatedAdc::reference_demo`]: empty for 0.3 s, 138.32 g dropped at
/// 0.3 s, removed at 2.0 s, 250 g dropped at 2.5 s, end at 4.0 s.
pub const REFERENCE_DEMO_EVENTS: [LoadEvent; 3] = [
    LoadEvent::step(0.3, 138.32),
    LoadEvent::step(2.0, 0.0),
    LoadEvent::step(2.5, 250.0),
];
/// End of the reference demo, s.
pub const REFERENCE_DEMO_END_S: f64 = 4.0;
/// The step the reference demo's SNR refers to, g.
pub const REFERENCE_STEP_G: f64 = 138.32;
/// The reference demo's SNR, dB (thesis eq. 4.39).
pub const REFERENCE_SNR_DB: f64 = 50.0;
/// The window over which the SNR's signal RMS is taken: 6,000 samples (1.5 s) from the drop.
pub const SNR_WINDOW_SAMPLES: usize = 6000;

/// The demo's script ([`REFERENCE_DEMO_EVENTS`], ending at [`REFERENCE_DEMO_END_S`]) after
/// `empty_s` more of empty pan at the start (0: the demo itself), in a script of `E` slots.
pub fn reference_demo_script<const E: usize>(empty_s: f64) -> Script<E> {
    let mut script = Script::new(REFERENCE_DEMO_END_S + empty_s);
    for event in REFERENCE_DEMO_EVENTS {
        // Three events in time order: refused only by a script of fewer than three slots.
        let _ = script.push(LoadEvent {
            time_s: event.time_s + empty_s,
            ..event
        });
    }
    script
}

impl SimulatedAdc<8> {
    /// The demo scene on the reference chain (16-bit ADC): see [`REFERENCE_DEMO_EVENTS`],
    /// white noise at 50 dB SNR relative to the 138.32 g step (eq. 4.39 over
    /// [`SNR_WINDOW_SAMPLES`]), plus the INA114's own noise.
    pub fn reference_demo(seed: u64) -> Self {
        Self::reference_demo_with_empty_start(seed, 0.0)
    }

    /// [`Self::reference_demo`] with the empty pan held `empty_s` longer at the start (the
    /// same noise), so that the first drop, too, lands after a long empty period.
    pub fn reference_demo_with_empty_start(seed: u64, empty_s: f64) -> Self {
        let chain = SensorChain::reference();
        let script = reference_demo_script(empty_s);
        let mut disturbances = Disturbances::white(white_noise_for_snr(
            &chain,
            REFERENCE_STEP_G,
            REFERENCE_SNR_DB,
            SNR_WINDOW_SAMPLES,
        ));
        disturbances.amplifier_noise = true;
        Self::new(chain, script, disturbances, seed)
    }
}

impl<const E: usize> SimulatedAdc<E> {
    /// The chain at rest with an empty platform at t = 0.
    pub fn new(
        chain: SensorChain,
        script: Script<E>,
        disturbances: Disturbances,
        seed: u64,
    ) -> Self {
        let mut noise = Gaussian::new(seed);
        let rate = 1.0 / chain.conversion_period_s();
        let vibration = Resonator::new(
            disturbances.vibration_rms_g,
            disturbances.vibration_hz,
            disturbances.vibration_bandwidth_hz,
            rate,
            &mut noise,
        );
        let mains_phase = 2.0 * core::f64::consts::PI * noise.uniform();
        Self {
            model: chain.discretise(0.0),
            chain,
            script,
            disturbances,
            state: DiscreteSensor::equilibrium(0.0),
            noise,
            vibration,
            mains_phase,
            creep_g: 0.0,
            conversions: 0,
            load_g: 0.0,
        }
    }

    /// The chain being simulated.
    pub fn chain(&self) -> &SensorChain {
        &self.chain
    }

    /// The script being played.
    pub fn script(&self) -> &Script<E> {
        &self.script
    }

    /// Static gain of the output code, counts per gram.
    pub fn counts_per_gram(&self) -> f64 {
        self.chain.counts_per_gram()
    }

    /// Code of the empty platform, noise-free (a real number; round it for integer use).
    pub fn zero_code(&self) -> f64 {
        self.chain.zero_code()
    }

    /// Time of the next sample, s.
    pub fn time_s(&self) -> f64 {
        self.conversions as f64 * self.chain.conversion_period_s()
    }

    /// The true load on the platform over the last conversion, g.
    pub fn load_g(&self) -> f64 {
        self.load_g
    }

    /// True once the script's end has been reached.
    pub fn is_finished(&self) -> bool {
        self.time_s() >= self.script.end_s()
    }

    /// One conversion, before quantisation, in codes of one conversion.
    fn convert(&mut self) -> f64 {
        let period = self.chain.conversion_period_s();
        let t = self.conversions as f64 * period;
        let load = self.script.load_over(self.conversions, period);
        if load != self.model.load_g {
            self.model = self.chain.discretise(load);
        }
        self.load_g = load;
        let d = &self.disturbances;
        let vibration = if d.vibration_rms_g > 0.0 {
            self.vibration.next(&mut self.noise)
        } else {
            0.0
        };
        let amplifier = if d.amplifier_noise {
            self.chain.amplifier_noise_g() * self.noise.standard()
        } else {
            0.0
        };
        let output_g = self
            .model
            .step(&mut self.state, [load, vibration, amplifier]);
        let creep_g = self.creep_g;
        if d.creep_fraction != 0.0 && d.creep_time_constant_s > 0.0 {
            let alpha = 1.0 - libm::exp(-period / d.creep_time_constant_s);
            self.creep_g += alpha * (d.creep_fraction * load - self.creep_g);
        }
        let mains = d.mains_amplitude_g
            * libm::sin(2.0 * core::f64::consts::PI * d.mains_hz * t + self.mains_phase);
        let white = if d.white_noise_g > 0.0 {
            d.white_noise_g * self.noise.standard()
        } else {
            0.0
        };
        let total_g = output_g + creep_g + d.drift_g_per_s * t + mains + white;
        self.conversions += 1;
        let volts = self.chain.zero_volts() + total_g * self.chain.volts_per_gram();
        volts / self.chain.adc.volts_per_code()
    }

    /// The next sample without quantisation or clipping (sum over the oversampled
    /// conversions), in codes: for studies of the estimator apart from the converter.
    pub fn read_analog(&mut self) -> f64 {
        let mut sum = 0.0;
        for _ in 0..self.chain.adc.oversampling.max(1) {
            sum += self.convert();
        }
        sum
    }
}

impl<const E: usize> AdcSource for SimulatedAdc<E> {
    fn max_code(&self) -> u32 {
        self.chain.adc.max_code()
    }

    fn read(&mut self) -> Result<u32, AdcError> {
        let top = f64::from(self.chain.adc.single_max_code());
        let mut sum: u32 = 0;
        for _ in 0..self.chain.adc.oversampling.max(1) {
            let code = libm::round(self.convert());
            // Written so that NaN lands on the lower rail, where it is flagged as saturated.
            let clipped = if code > 0.0 { code.min(top) } else { 0.0 };
            sum = sum.saturating_add(clipped as u32);
        }
        Ok(sum)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn script_refuses_out_of_order_and_overflow() {
        let mut script = Script::<2>::new(1.0);
        assert_eq!(script.push(LoadEvent::step(0.5, 10.0)), Ok(()));
        assert_eq!(
            script.push(LoadEvent::step(0.4, 10.0)),
            Err(ScriptError::OutOfOrder)
        );
        assert_eq!(
            script.push(LoadEvent::step(f64::NAN, 1.0)),
            Err(ScriptError::NotFinite)
        );
        assert_eq!(script.push(LoadEvent::step(0.6, 0.0)), Ok(()));
        assert_eq!(
            script.push(LoadEvent::step(0.7, 0.0)),
            Err(ScriptError::Full)
        );
    }

    #[test]
    fn ramp_moves_linearly() {
        let mut script = Script::<2>::new(1.0);
        script
            .push(LoadEvent {
                time_s: 0.1,
                mass_g: 100.0,
                ramp_s: 0.1,
            })
            .unwrap();
        let h = 0.001;
        assert_eq!(script.load_over(99, h), 0.0);
        assert!((script.load_over(100, h) - 0.5).abs() < 1e-9);
        assert!((script.load_over(149, h) - 49.5).abs() < 1e-9);
        assert_eq!(script.load_over(400, h), 100.0);
    }

    #[test]
    fn a_hand_overshoots_and_bounces_back_and_a_drop_carries_its_momentum() {
        let [rise, back] = placed_by_hand(1.0, 100.0, 150.0, 0.2, 0.1, 0.05);
        assert_eq!((rise.time_s, rise.mass_g, rise.ramp_s), (1.0, 155.0, 0.2));
        assert_eq!((back.time_s, back.mass_g, back.ramp_s), (1.2, 150.0, 0.05));
        // 50 g from 10 mm over 5 ms: the impulse (extra load × contact time, in g·s) is the
        // item's momentum over g: 50 g × 0.443 m/s / 9.807 m/s² = 2.258 g·s.
        let [impact, rest] = dropped_from_height(2.0, 100.0, 150.0, 0.010, 0.005);
        let impulse = (impact.mass_g - 150.0) * (rest.time_s - impact.time_s);
        assert!((impulse - 50.0 * (2.0 * 9.80665f64 * 0.01).sqrt() / 9.80665).abs() < 1e-9);
        assert_eq!((rest.mass_g, rest.ramp_s), (150.0, 0.0));
    }

    #[test]
    fn demo_reads_the_zero_then_the_load() {
        let mut adc = SimulatedAdc::reference_demo(7);
        let gain = adc.counts_per_gram();
        let zero = adc.zero_code();
        let mut empty = 0.0;
        for _ in 0..1000 {
            empty += f64::from(adc.read().unwrap());
        }
        empty /= 1000.0;
        let sigma_g = white_noise_for_snr(adc.chain(), REFERENCE_STEP_G, 50.0, SNR_WINDOW_SAMPLES);
        // The mean of 1,000 samples lies within 4 standard errors of the zero.
        assert!((empty - zero).abs() < 4.0 * sigma_g * gain / 1000f64.sqrt() + 0.5);
        // Settled at 1.9 s with 138.32 g: average 400 samples at 1.8–1.9 s.
        while adc.time_s() < 1.8 {
            adc.read().unwrap();
        }
        let mut loaded = 0.0;
        for _ in 0..400 {
            loaded += f64::from(adc.read().unwrap());
        }
        let mass = (loaded / 400.0 - zero) / gain;
        assert!((mass - 138.32).abs() < 0.15, "{mass}");
        assert!(!adc.is_finished());
    }

    #[test]
    fn same_seed_same_codes_other_seed_other_codes() {
        let mut a = SimulatedAdc::reference_demo(1);
        let mut b = SimulatedAdc::reference_demo(1);
        let mut c = SimulatedAdc::reference_demo(2);
        let mut differ = 0;
        for _ in 0..100 {
            let (x, y, z) = (a.read().unwrap(), b.read().unwrap(), c.read().unwrap());
            assert_eq!(x, y);
            differ += usize::from(x != z);
        }
        assert!(differ > 50);
    }
}
