//! The host half of the on-target bit-exactness check: the stored step response, the host
//! `f32` run of the same configurations, and the comparison with what the bare-metal
//! `core_check` binary (package `on-target`) printed under QEMU.
//!
//! The stored response (`tests/on-target/data/step_response.f32le`) is a noisy 2nd-order
//! step response generated here in `f64` with `libm` and an integer noise generator, then
//! rounded to `f32`; a test regenerates it and demands the stored bytes be identical
//! (set `UPDATE_ON_TARGET_DATA=1` to overwrite after an intended change).

use std::fmt;
use std::path::PathBuf;

use estimator_core::{Estimator, Reading, State, StepConfig, StepEstimator};
use rand_core::{RngCore, SeedableRng};
use rand_xoshiro::SplitMix64;

/// The configurations the bare-metal `core_check` binary runs, from its own crate.
pub use on_target::cases;

use cases::{CAPACITY, CASES, GAIN_PER_G, RESPONSE_FILE};

/// Sampling rate of the stored response.
pub const SAMPLE_RATE_HZ: f64 = 4_000.0;
/// Length of the stored response: 0.3 s.
pub const RESPONSE_SAMPLES: usize = 1_200;
/// The mass put on the pan.
pub const MASS_G: f64 = 138.32;
/// Undamped natural frequency of the pan/load-cell mechanics.
pub const NATURAL_FREQUENCY_HZ: f64 = 18.0;
/// Damping ratio of the mechanics.
pub const DAMPING_RATIO: f64 = 0.12;
/// Signal-to-noise ratio of the step against white noise, in dB.
pub const SNR_DB: f64 = 50.0;

/// Where the stored response lives.
pub fn response_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("on-target")
        .join("data")
        .join(RESPONSE_FILE)
}

/// Approximately standard normal: Irwin–Hall sum of 12 uniforms from SplitMix64 (a tiny
/// integer generator, identical on every platform) minus 6; exact arithmetic only, so the
/// stored bytes do not depend on a platform's libm.
fn normal(noise: &mut SplitMix64) -> f64 {
    let sum: f64 = (0..12)
        .map(|_| (noise.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
        .sum();
    sum - 6.0
}

/// The stored response, computed: `G·m·(1 − e^{−ζωt}(cos ω_d t + ζ/√(1−ζ²) sin ω_d t))`
/// plus white noise at [`SNR_DB`], in raw units with the zero offset removed.
pub fn generate_response() -> Vec<f32> {
    let omega = 2.0 * core::f64::consts::PI * NATURAL_FREQUENCY_HZ;
    let zeta = DAMPING_RATIO;
    let damped = omega * libm::sqrt(1.0 - zeta * zeta);
    let step_raw = f64::from(GAIN_PER_G) * MASS_G;
    let noise_rms = step_raw / libm::pow(10.0, SNR_DB / 20.0);
    let mut noise = SplitMix64::from_seed(0x005e_ed0f_10ad_ce11_u64.to_le_bytes());
    (0..RESPONSE_SAMPLES)
        .map(|k| {
            let t = k as f64 / SAMPLE_RATE_HZ;
            let envelope = libm::exp(-zeta * omega * t);
            let shape = 1.0
                - envelope
                    * (libm::cos(damped * t)
                        + zeta / libm::sqrt(1.0 - zeta * zeta) * libm::sin(damped * t));
            (step_raw * shape + noise_rms * normal(&mut noise)) as f32
        })
        .collect()
}

/// The stored response as the bytes of the file.
pub fn generate_response_bytes() -> Vec<u8> {
    generate_response()
        .iter()
        .flat_map(|sample| sample.to_le_bytes())
        .collect()
}

/// Decode `f32` little-endian samples.
pub fn decode_response(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

/// One reading as both sides report it: floats as bit patterns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    /// Index into [`cases::CASES`].
    pub case: usize,
    /// Sample index within the response.
    pub sample: usize,
    /// `W`, `E` or `I`.
    pub state: char,
    /// The [`estimator_core::InvalidReason`] discriminant when `state == 'I'`, else 0.
    pub reason: u8,
    /// Bits of the estimate, if any.
    pub estimate: Option<u32>,
    /// Bits of the a-priori residual, if any.
    pub residual: Option<u32>,
}

fn record(case: usize, sample: usize, reading: &Reading<f32>) -> Record {
    let (state, reason) = match reading.state {
        State::WarmingUp => ('W', 0),
        State::Estimating => ('E', 0),
        State::Invalid(reason) => ('I', reason as u8),
    };
    Record {
        case,
        sample,
        state,
        reason,
        estimate: reading.estimate.map(f32::to_bits),
        residual: reading.residual.map(f32::to_bits),
    }
}

/// Run every case on the host in `f32`, exactly as `core_check` does on the target.
pub fn host_records(response: &[f32]) -> Vec<Record> {
    let mut records = Vec::with_capacity(CASES.len() * response.len());
    for (index, case) in CASES.iter().enumerate() {
        let config = StepConfig::new(case.order, GAIN_PER_G)
            .with_decimation(case.decimation)
            .with_forgetting(case.forgetting);
        let mut estimator = StepEstimator::<f32, CAPACITY>::new(config)
            .unwrap_or_else(|error| panic!("case {index} {case:?} refused: {error}"));
        for (sample, &raw) in response.iter().enumerate() {
            records.push(record(index, sample, &estimator.push(raw)));
        }
    }
    records
}

/// Why the target's output could not be read.
#[derive(Debug, PartialEq, Eq)]
pub struct ParseError(pub String);

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ParseError {}

fn parse_bits(field: &str) -> Result<Option<u32>, ParseError> {
    if field == "-" {
        return Ok(None);
    }
    u32::from_str_radix(field, 16)
        .map(Some)
        .map_err(|_| ParseError(format!("bad float bits {field:?}")))
}

/// Parse `core_check`'s output: `begin`, one `r …` line per reading, `end`.
pub fn parse_target_output(text: &str) -> Result<Vec<Record>, ParseError> {
    let mut records = Vec::new();
    let mut begun = false;
    let mut ended = false;
    for line in text.lines() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        match fields.as_slice() {
            ["begin", ..] => begun = true,
            ["end"] => ended = true,
            ["r", case, sample, state, estimate, residual] => {
                let bad = |what: &str| ParseError(format!("bad {what} in line {line:?}"));
                let mut chars = state.chars();
                let state_char = chars.next().ok_or_else(|| bad("state"))?;
                let reason = chars.as_str().parse().map_err(|_| bad("reason"))?;
                records.push(Record {
                    case: case.parse().map_err(|_| bad("case"))?,
                    sample: sample.parse().map_err(|_| bad("sample"))?,
                    state: state_char,
                    reason,
                    estimate: parse_bits(estimate)?,
                    residual: parse_bits(residual)?,
                });
            }
            _ => {}
        }
    }
    if !begun || !ended {
        return Err(ParseError(format!(
            "output incomplete (begin: {begun}, end: {ended}, {} readings)",
            records.len()
        )));
    }
    Ok(records)
}

/// Distance in units in the last place between two `f32` bit patterns (0 = identical).
pub fn ulp_distance(a: u32, b: u32) -> u64 {
    // Map the sign-magnitude encoding onto a monotonic integer line.
    fn ordered(bits: u32) -> i64 {
        if bits & 0x8000_0000 != 0 {
            -((bits & 0x7fff_ffff) as i64)
        } else {
            bits as i64
        }
    }
    ordered(a).abs_diff(ordered(b))
}

/// Per-case agreement between host and target.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CaseAgreement {
    /// Readings compared.
    pub readings: usize,
    /// Readings whose state (or presence of estimate/residual) differs.
    pub state_mismatches: usize,
    /// Largest ulp distance of the estimates.
    pub max_estimate_ulp: u64,
    /// Largest ulp distance of the residuals.
    pub max_residual_ulp: u64,
    /// Estimates that are not bit-identical.
    pub estimate_differences: usize,
}

/// Compare the two runs reading by reading; `Err` if they do not even line up.
pub fn compare(host: &[Record], target: &[Record]) -> Result<Vec<CaseAgreement>, String> {
    if host.len() != target.len() {
        return Err(format!(
            "host has {} readings, target {}",
            host.len(),
            target.len()
        ));
    }
    let mut agreement = vec![CaseAgreement::default(); CASES.len()];
    for (h, t) in host.iter().zip(target) {
        if (h.case, h.sample) != (t.case, t.sample) || h.case >= CASES.len() {
            return Err(format!("readings out of step: host {h:?}, target {t:?}"));
        }
        let case = &mut agreement[h.case];
        case.readings += 1;
        if (h.state, h.reason) != (t.state, t.reason)
            || h.estimate.is_some() != t.estimate.is_some()
            || h.residual.is_some() != t.residual.is_some()
        {
            case.state_mismatches += 1;
        }
        if let (Some(a), Some(b)) = (h.estimate, t.estimate) {
            let ulp = ulp_distance(a, b);
            case.max_estimate_ulp = case.max_estimate_ulp.max(ulp);
            if ulp != 0 {
                case.estimate_differences += 1;
            }
        }
        if let (Some(a), Some(b)) = (h.residual, t.residual) {
            case.max_residual_ulp = case.max_residual_ulp.max(ulp_distance(a, b));
        }
    }
    Ok(agreement)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ulp_distance_counts_across_zero_and_within_a_binade() {
        assert_eq!(ulp_distance(1.0f32.to_bits(), 1.0f32.to_bits()), 0);
        let next = f32::from_bits(1.0f32.to_bits() + 1);
        assert_eq!(ulp_distance(1.0f32.to_bits(), next.to_bits()), 1);
        assert_eq!(ulp_distance(0.0f32.to_bits(), (-0.0f32).to_bits()), 0);
        let tiny = f32::from_bits(1);
        assert_eq!(ulp_distance(tiny.to_bits(), (-tiny).to_bits()), 2);
    }

    #[test]
    fn parser_reads_readings_and_rejects_truncated_output() {
        let text = "begin 12 2\nr 0 0 W0 - -\nr 0 1 E0 43091eb8 bf800000\nr 0 2 I3 - -\nend\n";
        let records = parse_target_output(text).expect("complete output parses");
        assert_eq!(records.len(), 3);
        assert_eq!(records[1].estimate, Some(0x4309_1eb8));
        assert_eq!(records[1].residual, Some(0xbf80_0000));
        assert_eq!((records[2].state, records[2].reason), ('I', 3));
        // A guest that died half-way (no `end`) must not pass as a shorter, matching run.
        assert!(parse_target_output("begin 12 2\nr 0 0 W0 - -\n").is_err());
    }

    #[test]
    fn comparison_flags_a_one_ulp_change_and_a_state_change() {
        let response = generate_response();
        let host = host_records(&response[..100]);
        let mut target = host.clone();
        let estimating = target
            .iter()
            .position(|r| r.estimate.is_some())
            .expect("some reading estimates within 100 samples");
        target[estimating].estimate = target[estimating].estimate.map(|bits| bits + 1);
        let last = target.len() - 1;
        target[last].state = 'I';
        let agreement = compare(&host, &target).expect("same shape");
        let total_ulp: u64 = agreement.iter().map(|a| a.max_estimate_ulp).sum();
        let total_states: usize = agreement.iter().map(|a| a.state_mismatches).sum();
        assert_eq!(total_ulp, 1);
        assert_eq!(total_states, 1);
    }

    #[test]
    fn stored_response_matches_its_generator() {
        let path = response_path();
        let generated = generate_response_bytes();
        if std::env::var_os("UPDATE_ON_TARGET_DATA").is_some() {
            std::fs::write(&path, &generated).expect("write the stored response");
        }
        let stored =
            std::fs::read(&path).unwrap_or_else(|error| panic!("read {}: {error}", path.display()));
        assert!(
            stored == generated,
            "{} differs from generate_response(); rerun with UPDATE_ON_TARGET_DATA=1 if intended",
            path.display()
        );
    }

    #[test]
    fn stored_response_is_a_plausible_noisy_step() {
        let response = generate_response();
        let step_raw = f64::from(GAIN_PER_G) * MASS_G;
        let tail = &response[response.len() - 200..];
        let tail_mean = tail.iter().map(|&s| f64::from(s)).sum::<f64>() / tail.len() as f64;
        // 0.25 s in at ζ = 0.12 and 18 Hz the ringing is down to a few percent.
        assert!(
            (tail_mean / step_raw - 1.0).abs() < 0.05,
            "tail mean {tail_mean}"
        );
        assert!(response[0].abs() < 0.01 * step_raw as f32);
    }
}
