//! The input-shaper FIR (Richiedei and Trevisani, Mechanical Systems and Signal Processing
//! 98, 2018): a few positive taps, summing to one, whose zeros sit on the cell's mode, so the
//! mode's ring leaves the output once the taps have seen half a damped period.
//!
//! ## The taps in discrete time
//! The zero-vibration (ZV) shaper puts two impulses half a damped period apart, weighted
//! `1 : K` with `K = e^{−ζπ/√(1−ζ²)}`. Half a period is rarely a whole number of samples, so
//! here the second impulse is split between the samples `N` and `N + 1` that straddle it
//! (`N = ⌊π/θ⌋`, `θ` the pole's angle): the three taps `a0 + a1·z^{−N} + a2·z^{−N−1}` solve
//! `F(1) = 1` and `F(p) = 0` at the cell's discrete pole `p` exactly, so the mode is
//! cancelled exactly, not to within a rounding of the delay. When `N·θ = π` they are the
//! ZV shaper's `1/(1 + K)`, `K/(1 + K)`, 0. ZVD is ZV applied twice (a double zero on the
//! mode: a flat null, less sensitive to a resonance that moved with the load), ZVDD three
//! times; each stage keeps `N + 1` past values of its input.
//!
//! What must never happen: taps that do not sum to one (a gain error), or a delay line
//! longer than the capacity `M` (refused at configuration).

use super::mode::CellMode;
use super::Prefilter;
use crate::numerics::real::Real;
use crate::reading::ConfigError;

/// How many times the ZV stage is applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ShaperKind {
    /// Zero vibration: one stage, half a damped period long.
    Zv,
    /// Zero vibration and derivative: two stages, one damped period.
    Zvd,
    /// Three stages, one and a half damped periods.
    Zvdd,
}

impl ShaperKind {
    /// The ZV stages in cascade.
    pub fn stages(self) -> usize {
        match self {
            ShaperKind::Zv => 1,
            ShaperKind::Zvd => 2,
            ShaperKind::Zvdd => 3,
        }
    }
}

/// The mode a [`Shaper`] cancels and how.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ShaperConfig {
    /// The cell's mode (oscillatory, `ζ < 1`).
    pub cell: CellMode,
    /// ZV, ZVD or ZVDD.
    pub kind: ShaperKind,
}

/// The shaper FIR with room for `M` past values over all its stages.
#[derive(Clone, Debug)]
pub struct Shaper<T, const M: usize> {
    /// `a0, a1, a2` at the delays 0, `N`, `N + 1`.
    taps: [T; 3],
    /// `N + 1`: the past values each stage keeps.
    span: usize,
    stages: usize,
    /// Stage `s` keeps its input's past values in `line[s·span..(s + 1)·span]`, a ring.
    line: [T; M],
    /// In every stage's ring, where its oldest value (`N + 1` samples back) is.
    oldest: usize,
    started: bool,
}

impl<T: Real, const M: usize> Shaper<T, M> {
    /// The shaper, or the field that is out of its domain.
    pub fn new(config: ShaperConfig) -> Result<Self, ConfigError> {
        config.cell.validate(true)?;
        let (taps, delay) = zv_taps(&config.cell);
        let span = delay + 1;
        let stages = config.kind.stages();
        if span * stages > M {
            return Err(ConfigError::Filter("delay line capacity M"));
        }
        let (a0, a1) = (T::from_f64(taps[0]), T::from_f64(taps[1]));
        Ok(Self {
            // The last tap closes the sum in `T`, so that the gain at DC is one there too.
            taps: [a0, a1, T::ONE - a0 - a1],
            span,
            stages,
            line: [T::ZERO; M],
            oldest: 0,
            started: false,
        })
    }

    /// The taps `a0, a1, a2` and the delay `N` of `a1` (`a2` at `N + 1`).
    pub fn taps(&self) -> ([T; 3], usize) {
        (self.taps, self.span - 1)
    }
}

/// The ZV stage's taps at the delays 0, `N`, `N + 1` and `N` (see the module docs), in `f64`.
fn zv_taps(cell: &CellMode) -> ([f64; 3], usize) {
    let (rho, theta) = cell.pole();
    // θ < π below the Nyquist frequency, so N ≥ 1 and π < (N + 1)·θ < 2π.
    let delay = libm::floor(core::f64::consts::PI / theta) as usize;
    // p^{−n} = ρ^{−n}·e^{−jnθ}, for n = N and N + 1.
    let inverse_power = |n: usize| {
        let magnitude = libm::pow(rho, -(n as f64));
        let angle = n as f64 * theta;
        (magnitude * libm::cos(angle), -magnitude * libm::sin(angle))
    };
    let (u_re, u_im) = inverse_power(delay);
    let (v_re, v_im) = inverse_power(delay + 1);
    // a1·Im u + a2·Im v = 0 and a1·(1 − Re u) + a2·(1 − Re v) = 1 (F(1) = 1 less Re F(p) = 0).
    let ratio = -u_im / v_im;
    let a1 = 1.0 / ((1.0 - u_re) + ratio * (1.0 - v_re));
    let a2 = ratio * a1;
    ([1.0 - a1 - a2, a1, a2], delay)
}

impl<T: Real, const M: usize> Prefilter<T> for Shaper<T, M> {
    #[inline]
    fn filter(&mut self, x: T) -> T {
        if !self.started {
            // At rest at the first sample: every stage's past input was this value.
            self.line[..self.span * self.stages].fill(x);
            self.started = true;
        }
        let [a0, a1, a2] = self.taps;
        let (oldest, next) = (self.oldest, (self.oldest + 1) % self.span);
        let mut value = x;
        for ring in self.line.chunks_exact_mut(self.span).take(self.stages) {
            let output = a0 * value + a1 * ring[next] + a2 * ring[oldest];
            ring[oldest] = value;
            value = output;
        }
        self.oldest = next;
        value
    }

    fn restart(&mut self) {
        self.oldest = 0;
        self.started = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATE: f64 = 4000.0;

    fn cell(natural_frequency_hz: f64) -> CellMode {
        CellMode {
            natural_frequency_hz,
            damping_ratio: 0.03,
            sample_rate_hz: RATE,
        }
    }

    fn shaper<T: Real>(kind: ShaperKind, natural_frequency_hz: f64) -> Shaper<T, 512> {
        Shaper::new(ShaperConfig {
            cell: cell(natural_frequency_hz),
            kind,
        })
        .unwrap()
    }

    /// A free decay of the mode at `frequency_hz` around `level`, amplitude 10.
    fn decay(frequency_hz: f64, level: f64, k: usize) -> f64 {
        let omega = 2.0 * core::f64::consts::PI * frequency_hz;
        let t = k as f64 / RATE;
        let damped = omega * (1.0f64 - 0.03 * 0.03).sqrt();
        level + 10.0 * (-0.03 * omega * t).exp() * (damped * t).cos()
    }

    /// The largest |output − level| from sample `from` to 2 s, for a decay at `actual_hz`.
    fn residual(kind: ShaperKind, actual_hz: f64, from: usize) -> f64 {
        let mut filter = shaper::<f64>(kind, 25.0);
        (0..8000)
            .map(|k| (k, filter.filter(decay(actual_hz, 100.0, k))))
            .filter(|(k, _)| *k >= from)
            .map(|(_, y)| (y - 100.0).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn the_taps_are_positive_and_sum_to_one() {
        for frequency_hz in [5.0, 24.7, 25.0, 32.6, 400.0, 1500.0] {
            let (taps, delay) = shaper::<f64>(ShaperKind::Zv, frequency_hz).taps();
            assert!(taps.iter().all(|&a| a >= 0.0), "{frequency_hz}: {taps:?}");
            assert!((taps.iter().sum::<f64>() - 1.0).abs() < 1e-15, "{taps:?}");
            let half_period = RATE / (2.0 * frequency_hz * (1.0f64 - 0.03 * 0.03).sqrt());
            assert_eq!(delay, half_period.floor() as usize);
        }
        // A half period of whole samples: the textbook ZV impulses 1/(1 + K), K/(1 + K).
        let frequency_hz = RATE / 160.0 / (1.0f64 - 0.03 * 0.03).sqrt();
        let (taps, delay) = shaper::<f64>(ShaperKind::Zv, frequency_hz).taps();
        let k = (-0.03 * core::f64::consts::PI / (1.0f64 - 0.03 * 0.03).sqrt()).exp();
        assert_eq!(delay, 80);
        assert!((taps[0] - 1.0 / (1.0 + k)).abs() < 1e-9, "{taps:?}");
        assert!(taps[2].abs() < 1e-9, "{taps:?}");
    }

    /// On the tuned mode every kind cancels the ring once its span has passed (ZVDD: 1.5
    /// periods, 3·81 samples at 25 Hz): 1e-9 of the amplitude left, against 7.5 of 10 at
    /// that time without the shaper.
    #[test]
    fn the_tuned_mode_is_cancelled() {
        for kind in [ShaperKind::Zv, ShaperKind::Zvd, ShaperKind::Zvdd] {
            let left = residual(kind, 25.0, 243);
            assert!(left < 1e-8, "{kind:?}: {left}");
        }
        assert!((decay(25.0, 100.0, 243) - 100.0).abs() > 7.0);
    }

    /// Off the tuned mode (the resonance 5 % lower, as a heavier load makes it), the double
    /// zero of ZVD leaves less than ZV, and ZVDD less again.
    #[test]
    fn more_stages_are_less_sensitive_to_a_moved_resonance() {
        let left = [ShaperKind::Zv, ShaperKind::Zvd, ShaperKind::Zvdd]
            .map(|kind| residual(kind, 25.0 * 0.95, 243));
        assert!(left[0] < 10.0 * 0.2, "{left:?}");
        assert!(
            left[1] < 0.5 * left[0] && left[2] < 0.5 * left[1],
            "{left:?}"
        );
    }

    /// `f32` against `f64` on the same decay around 138.32: within 1e-6 of the level (3e-7
    /// measured: taps rounded to `f32` with their sum closed in `f32`, samples of 138 g
    /// rounded by up to 7.6e-6 g, three products a stage).
    #[test]
    fn f32_follows_f64() {
        let mut wide = shaper::<f64>(ShaperKind::Zvd, 25.0);
        let mut narrow = shaper::<f32>(ShaperKind::Zvd, 25.0);
        let mut worst = 0.0f64;
        for k in 0..6000 {
            let x = decay(25.0, 138.32, k);
            let difference = f64::from(narrow.filter(x as f32)) - wide.filter(x);
            worst = worst.max(difference.abs());
        }
        assert!(worst < 1e-6 * 138.32, "{worst}");
    }

    #[test]
    fn impossible_configurations_name_their_field() {
        let refused = |cell: CellMode, kind| Shaper::<f32, 100>::new(ShaperConfig { cell, kind });
        // 25 Hz at 4 kHz: 81 values a stage; two stages do not fit in 100.
        assert!(refused(cell(25.0), ShaperKind::Zv).is_ok());
        assert_eq!(
            refused(cell(25.0), ShaperKind::Zvd).err(),
            Some(ConfigError::Filter("delay line capacity M"))
        );
        let undamped_above_one = CellMode {
            damping_ratio: 1.5,
            ..cell(25.0)
        };
        assert_eq!(
            refused(undamped_above_one, ShaperKind::Zv).err(),
            Some(ConfigError::Filter("damping_ratio"))
        );
        assert_eq!(
            refused(cell(f64::NAN), ShaperKind::Zv).err(),
            Some(ConfigError::Filter("natural_frequency_hz"))
        );
    }
}
