//! The 5th-order weighing sensor: load-cell mechanics, INA114, 3rd-order Butterworth, ADC.
//!
//! ## State space (continuous time), in grams
//! Every state is expressed as an equivalent static load in grams, so the matrices are well
//! scaled and the static gain from the load to the filter output is exactly one:
//!
//! - `p`: the cell's deflection from the empty-platform equilibrium, as the load that would
//!   hold it there statically (`p = k·δ/g`);
//! - `q = ṗ / ω_s`, with the fixed scaling rate `ω_s = 2π·25 rad/s` (fixed, so the state
//!   stays continuous when the load changes);
//! - `f1`: the first-order section of the Butterworth; `f2`, `f3 = ḟ2/ω_c`: its second-order
//!   section. `f2` is the filter output.
//!
//! ```text
//! ṗ  = ω_s q
//! q̇  = (ω²/ω_s)(M + d − p) − 2ζω q          ω² = k/(m_platform + M), 2ζω = c/(m_platform + M)
//! ḟ1 = ω_c (p + e − f1)                       e: INA114 input noise, referred to grams
//! ḟ2 = ω_c f3
//! ḟ3 = ω_c (f1 − f2 − f3)                     H(s) = ω_c³ / ((s + ω_c)(s² + ω_c s + ω_c²))
//! ```
//!
//! Inputs: `M` the load on the platform, `d` a force disturbance (floor vibration) as an
//! equivalent load, `e` the amplifier's input-referred noise. The mass changes the matrices
//! (the natural frequency depends on the load), so a step of mass is an LTI system *for the
//! new mass* (thesis eq. 2.2): the state carries over, the matrices are re-discretised.
//!
//! ## Discretisation
//! Exact zero-order hold: `exp([[A, B], [0, 0]]·h) = [[Φ, Γ], [0, I]]` (see [`crate::expm`]).
//! Never through a transfer-function polynomial: at 4 kHz its coefficients cancel to within
//! rounding.

use crate::expm::{self, Square};

/// Standard gravity, m/s².
pub const STANDARD_GRAVITY: f64 = 9.806_65;
/// The sample rate of the whole project's ADC, Hz.
pub const SAMPLE_RATE_HZ: f64 = 4000.0;
/// The fixed rate that scales the velocity state, rad/s.
const VELOCITY_SCALE_RAD_S: f64 = 2.0 * core::f64::consts::PI * 25.0;

/// Number of states of the sensor (2 mechanical + 3 filter).
pub const STATES: usize = 5;
/// Number of inputs: load, force disturbance, amplifier input noise (all in grams).
pub const INPUTS: usize = 3;
const AUGMENTED: usize = STATES + INPUTS;

/// The mechanics of the load cell with its platform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoadCell {
    /// Moving mass without load: the platform and the cell's free end, kg.
    pub platform_mass_kg: f64,
    /// Spring constant of the cell (with its mounting), N/m.
    pub stiffness_n_per_m: f64,
    /// Viscous damping, N·s/m.
    pub damping_n_s_per_m: f64,
    /// Rated capacity, g.
    pub capacity_g: f64,
    /// Rated output, mV per V of excitation, at capacity.
    pub rated_output_mv_per_v: f64,
    /// Bridge excitation, V.
    pub excitation_v: f64,
}

impl LoadCell {
    /// A cell whose stiffness and damping are chosen so that, carrying `design_load_g`, it
    /// rings at `ring_hz` with damping ratio `damping_ratio`.
    pub fn designed(
        platform_mass_kg: f64,
        design_load_g: f64,
        ring_hz: f64,
        damping_ratio: f64,
    ) -> Self {
        let moving_kg = platform_mass_kg + design_load_g * 1e-3;
        // ring_hz is the undamped natural frequency; at ζ = 0.03 the damped one is 0.05% lower.
        let omega = 2.0 * core::f64::consts::PI * ring_hz;
        Self {
            platform_mass_kg,
            stiffness_n_per_m: moving_kg * omega * omega,
            damping_n_s_per_m: 2.0 * damping_ratio * moving_kg * omega,
            capacity_g: 600.0,
            rated_output_mv_per_v: 2.0,
            excitation_v: 5.0,
        }
    }

    /// The reference cell: a Tedea-Huntleigh 1004-class single-point cell, 600 g capacity,
    /// 2 mV/V rated output at 5 V excitation, on a 120 g platform, with stiffness and damping
    /// chosen so that it rings at 25 Hz with damping ratio 0.03 when carrying 138.32 g.
    pub fn reference() -> Self {
        Self::designed(0.120, 138.32, 25.0, 0.03)
    }

    /// Undamped natural frequency with `load_g` on the platform, rad/s (ω² = k/(m_p + M)).
    pub fn natural_frequency_rad_s(&self, load_g: f64) -> f64 {
        libm::sqrt(self.stiffness_n_per_m / self.moving_mass_kg(load_g))
    }

    /// Damping ratio with `load_g` on the platform.
    pub fn damping_ratio(&self, load_g: f64) -> f64 {
        self.damping_n_s_per_m
            / (2.0 * libm::sqrt(self.stiffness_n_per_m * self.moving_mass_kg(load_g)))
    }

    fn moving_mass_kg(&self, load_g: f64) -> f64 {
        // A negative load (a lift-off) is not a mass; never let the moving mass vanish.
        self.platform_mass_kg + load_g.max(0.0) * 1e-3
    }

    /// Bridge output per gram of load, V/g.
    pub fn bridge_volts_per_gram(&self) -> f64 {
        self.rated_output_mv_per_v * 1e-3 * self.excitation_v / self.capacity_g
    }
}

/// The INA114 instrumentation amplifier.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ina114 {
    /// Gain-setting resistor R_G, Ω; gain = 1 + 50 kΩ / R_G.
    pub gain_resistor_ohm: f64,
    /// Input offset voltage, V.
    pub input_offset_v: f64,
    /// Voltage on the reference pin, which shifts the output, V.
    pub output_reference_v: f64,
    /// Input-referred voltage noise density, V/√Hz.
    pub input_noise_v_per_rt_hz: f64,
}

impl Ina114 {
    /// The reference front end: R_G = 300 Ω (gain 167.7), 25 µV input offset (the INA114BP
    /// maximum is 50 µV), 0.3 V on the reference pin so the empty pan sits above the ADC's
    /// lower rail, 11 nV/√Hz (datasheet, G ≥ 100, 1 kHz).
    pub fn reference() -> Self {
        Self {
            gain_resistor_ohm: 300.0,
            input_offset_v: 25e-6,
            output_reference_v: 0.3,
            input_noise_v_per_rt_hz: 11e-9,
        }
    }

    /// Voltage gain.
    pub fn gain(&self) -> f64 {
        1.0 + 50_000.0 / self.gain_resistor_ohm
    }
}

/// The converter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Adc {
    /// Resolution, bits (12 or 16 in our scenes; 1..=24 accepted).
    pub bits: u32,
    /// Full-scale reference voltage, V.
    pub reference_v: f64,
    /// Conversions summed per output sample (1 = none); the output code grows accordingly.
    pub oversampling: u16,
}

impl Adc {
    /// A 16-bit converter with a 2.5 V reference, no oversampling.
    pub fn reference() -> Self {
        Self {
            bits: 16,
            reference_v: 2.5,
            oversampling: 1,
        }
    }

    /// Largest code of one conversion.
    pub fn single_max_code(&self) -> u32 {
        let bits = self.bits.clamp(1, 24);
        (1u32 << bits) - 1
    }

    /// Largest output code (with oversampling).
    pub fn max_code(&self) -> u32 {
        self.single_max_code()
            .saturating_mul(u32::from(self.oversampling.max(1)))
    }

    /// Volts per code of one conversion.
    pub fn volts_per_code(&self) -> f64 {
        self.reference_v / f64::from(self.single_max_code() + 1)
    }
}

/// The whole chain: cell, amplifier, anti-alias filter and converter at one sample rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorChain {
    /// The load cell.
    pub cell: LoadCell,
    /// The instrumentation amplifier.
    pub amplifier: Ina114,
    /// Cut-off of the 3rd-order Butterworth low-pass, Hz.
    pub filter_cutoff_hz: f64,
    /// The converter.
    pub adc: Adc,
    /// Output samples per second (before oversampling), Hz.
    pub sample_rate_hz: f64,
}

impl SensorChain {
    /// The reference chain: [`LoadCell::reference`], [`Ina114::reference`], 100 Hz
    /// Butterworth, [`Adc::reference`] (16 bits), 4 kHz.
    pub fn reference() -> Self {
        Self {
            cell: LoadCell::reference(),
            amplifier: Ina114::reference(),
            filter_cutoff_hz: 100.0,
            adc: Adc::reference(),
            sample_rate_hz: SAMPLE_RATE_HZ,
        }
    }

    /// Volts at the ADC input per gram of load.
    pub fn volts_per_gram(&self) -> f64 {
        self.cell.bridge_volts_per_gram() * self.amplifier.gain()
    }

    /// Volts at the ADC input with the empty platform, noise-free.
    pub fn zero_volts(&self) -> f64 {
        let preload_v = self.cell.bridge_volts_per_gram() * self.cell.platform_mass_kg * 1e3;
        self.amplifier.output_reference_v
            + self.amplifier.gain() * (self.amplifier.input_offset_v + preload_v)
    }

    /// Static gain of the output code, counts per gram (with oversampling).
    pub fn counts_per_gram(&self) -> f64 {
        self.volts_per_gram() / self.adc.volts_per_code() * f64::from(self.adc.oversampling.max(1))
    }

    /// Output code of the empty platform, noise-free (with oversampling), as a real number.
    pub fn zero_code(&self) -> f64 {
        self.zero_volts() / self.adc.volts_per_code() * f64::from(self.adc.oversampling.max(1))
    }

    /// Time between conversions, s (the sample period divided by the oversampling).
    pub fn conversion_period_s(&self) -> f64 {
        1.0 / (self.sample_rate_hz * f64::from(self.adc.oversampling.max(1)))
    }

    /// The amplifier's input noise referred to grams, as the standard deviation of a
    /// piecewise-constant input over one conversion period (white over the Nyquist band).
    pub fn amplifier_noise_g(&self) -> f64 {
        let nyquist_hz = 0.5 / self.conversion_period_s();
        self.amplifier.input_noise_v_per_rt_hz * libm::sqrt(nyquist_hz)
            / self.cell.bridge_volts_per_gram()
    }

    /// The continuous-time state-space matrices (A, B) with `load_g` on the platform.
    pub fn continuous(&self, load_g: f64) -> ([[f64; STATES]; STATES], [[f64; INPUTS]; STATES]) {
        let omega = self.cell.natural_frequency_rad_s(load_g);
        let two_zeta_omega = 2.0 * self.cell.damping_ratio(load_g) * omega;
        let cutoff = 2.0 * core::f64::consts::PI * self.filter_cutoff_hz;
        let scale = VELOCITY_SCALE_RAD_S;
        let stiffness = omega * omega / scale;
        let a = [
            [0.0, scale, 0.0, 0.0, 0.0],
            [-stiffness, -two_zeta_omega, 0.0, 0.0, 0.0],
            [cutoff, 0.0, -cutoff, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, cutoff],
            [0.0, 0.0, cutoff, -cutoff, -cutoff],
        ];
        let b = [
            [0.0, 0.0, 0.0],
            [stiffness, stiffness, 0.0],
            [0.0, 0.0, cutoff],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
        ];
        (a, b)
    }

    /// The exact ZOH discretisation over one conversion period with `load_g` on the platform.
    pub fn discretise(&self, load_g: f64) -> DiscreteSensor {
        self.discretise_over(load_g, self.conversion_period_s())
    }

    /// The exact ZOH discretisation over `period_s`.
    pub fn discretise_over(&self, load_g: f64, period_s: f64) -> DiscreteSensor {
        let (a, b) = self.continuous(load_g);
        let mut augmented: Square<AUGMENTED> = [[0.0; AUGMENTED]; AUGMENTED];
        for row in 0..STATES {
            for col in 0..STATES {
                augmented[row][col] = a[row][col] * period_s;
            }
            for input in 0..INPUTS {
                augmented[row][STATES + input] = b[row][input] * period_s;
            }
        }
        let e = expm::exp(&augmented);
        let mut transition = [[0.0; STATES]; STATES];
        let mut input = [[0.0; INPUTS]; STATES];
        for row in 0..STATES {
            transition[row].copy_from_slice(&e[row][..STATES]);
            input[row].copy_from_slice(&e[row][STATES..]);
        }
        DiscreteSensor {
            transition,
            input,
            load_g,
        }
    }
}

/// The sensor discretised for one load: `z(k+1) = Φ z(k) + Γ u(k)`, output `f2 = z[3]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiscreteSensor {
    /// Φ.
    pub transition: [[f64; STATES]; STATES],
    /// Γ, columns: load, force disturbance, amplifier noise.
    pub input: [[f64; INPUTS]; STATES],
    /// The load this discretisation holds for, g.
    pub load_g: f64,
}

/// Index of the filter output in the state vector.
pub const OUTPUT_STATE: usize = 3;

impl DiscreteSensor {
    /// One step of the state; returns the output *before* the step (the sample at this
    /// instant: the load applied now shows from the next sample on).
    pub fn step(&self, state: &mut [f64; STATES], inputs: [f64; INPUTS]) -> f64 {
        let output = state[OUTPUT_STATE];
        let mut next = [0.0; STATES];
        for row in 0..STATES {
            let mut sum = 0.0;
            for col in 0..STATES {
                sum += self.transition[row][col] * state[col];
            }
            for input in 0..INPUTS {
                sum += self.input[row][input] * inputs[input];
            }
            next[row] = sum;
        }
        *state = next;
        output
    }

    /// The state the sensor settles to under a constant load (all derivatives zero).
    pub fn equilibrium(load_g: f64) -> [f64; STATES] {
        [load_g, 0.0, load_g, load_g, 0.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_cell_rings_at_25_hz_with_zeta_003() {
        let cell = LoadCell::reference();
        let f = cell.natural_frequency_rad_s(138.32) / (2.0 * core::f64::consts::PI);
        assert!((f - 25.0).abs() < 1e-9, "{f}");
        assert!((cell.damping_ratio(138.32) - 0.03).abs() < 1e-12);
        // Heavier loads ring lower: ω² = k/(m_p + M).
        assert!(cell.natural_frequency_rad_s(250.0) < cell.natural_frequency_rad_s(138.32));
    }

    #[test]
    fn static_gain_is_one_gram_per_gram() {
        let chain = SensorChain::reference();
        let model = chain.discretise(138.32);
        let mut state = DiscreteSensor::equilibrium(138.32);
        let before = state;
        model.step(&mut state, [138.32, 0.0, 0.0]);
        for (a, b) in state.iter().zip(before.iter()) {
            assert!((a - b).abs() < 1e-9, "{state:?}");
        }
    }
}
