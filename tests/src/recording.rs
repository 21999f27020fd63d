//! Record → calibrate → upload, the loop a user runs to fit the method to their own cell,
//! end to end on the QEMU board: the board plays the record scene
//! (`qemu_scenes::record_scene`, three drops of 138.32 g) while the harness types `record`
//! on the settled empty pan before each drop ([`RecordScript`]); the board writes each
//! recording on its console; `host-sim records` turns the transcript into CSVs;
//! `host-sim calibrate` chooses a method from them; the harness types `method <spec>` on
//! the next run ([`UploadScript`]), which must weigh the demo's drops within its criteria.
//!
//! What the recordings must be ([`check_recordings`]): three, each the board's whole
//! capture (5,000 samples, none lost or saturated), each exactly the codes the scene's
//! converter produced at those samples (found in [`scene_codes`]: nothing reordered,
//! dropped or invented on the way) and starting 0.25 s before the detected landing, which
//! lies within 20 ms after the true one.

use estimator_core::sensor::AdcSource;
use host_sim::qemu_scenes;
use host_sim::recording::console::{unpack, ConsoleRecording};

use crate::e2e::{ReadoutLine, SAMPLE_RATE_HZ};

/// The scene's name on QEMU's semihosting command line.
pub const SCENE_NAME: &str = "record";
/// The line that arms a recording.
pub const RECORD_LINE: &str = "record\n";
/// Samples a recording holds on the QEMU board (`firmware::pipeline::RECORD_SAMPLES`).
pub const RECORD_SAMPLES: usize = 5_000;
/// Samples of it before the detected load change (a fifth).
pub const RECORD_BEFORE: usize = RECORD_SAMPLES / 5;
/// The detected landing may lag the true one by this much (the onset detection's lag is
/// about 10 samples at 50 dB).
const MAX_DETECTION_LAG_S: f64 = 0.02;

/// What a harness types on the console after each readout line of a run, and what the
/// board wrote there (kept when the run ends).
pub trait ConsoleScript {
    /// The console lines to type after `line`, if any.
    fn respond(&mut self, line: &ReadoutLine) -> Option<String>;
    /// Keep what the board wrote on its console.
    fn record_console(&mut self, lines: Vec<String>);
}

/// Arms `record` on the empty pan before each of the scene's drops: on the first readout
/// line, then once the pan reads `Empty` again between a removal and the next drop (the
/// windows leave 0.5 s or more on each side).
#[derive(Clone, Debug, Default)]
pub struct RecordScript {
    sent: usize,
    transcript: Vec<String>,
}

impl RecordScript {
    /// Nothing typed yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// `record` lines typed.
    pub fn sent(&self) -> usize {
        self.sent
    }

    /// What the board wrote on its console.
    pub fn transcript(&self) -> &[String] {
        &self.transcript
    }
}

impl ConsoleScript for RecordScript {
    fn respond(&mut self, line: &ReadoutLine) -> Option<String> {
        let drops = qemu_scenes::RECORD_SCENE_DROPS_S;
        let time_s = line.time_s();
        let due = match self.sent {
            0 => time_s < drops[0] - 0.5,
            armed if armed < drops.len() => {
                let removal_s = drops[armed - 1] + qemu_scenes::RECORD_SCENE_HOLD_S;
                time_s > removal_s + 0.4 && time_s < drops[armed] - 0.5 && line.state == "Empty"
            }
            _ => false,
        };
        if !due {
            return None;
        }
        self.sent += 1;
        Some(RECORD_LINE.into())
    }

    fn record_console(&mut self, lines: Vec<String>) {
        self.transcript = lines;
    }
}

/// Types `method <spec>` on the first readout line (the method `host-sim calibrate`
/// chose), once.
#[derive(Clone, Debug)]
pub struct UploadScript {
    spec: String,
    sent: bool,
    transcript: Vec<String>,
}

impl UploadScript {
    /// Upload `spec` (a `weighing.toml`'s `method.spec`).
    pub fn new(spec: &str) -> Self {
        Self {
            spec: spec.to_string(),
            sent: false,
            transcript: Vec::new(),
        }
    }

    /// What the board wrote on its console.
    pub fn transcript(&self) -> &[String] {
        &self.transcript
    }

    /// The board's answer to the upload, if it gave one.
    pub fn answer(&self) -> Option<&str> {
        self.transcript
            .iter()
            .find(|line| line.starts_with("OK method") || line.starts_with("ERR method"))
            .map(String::as_str)
    }
}

impl ConsoleScript for UploadScript {
    fn respond(&mut self, _line: &ReadoutLine) -> Option<String> {
        if self.sent {
            return None;
        }
        self.sent = true;
        Some(format!("method {}\n", self.spec))
    }

    fn record_console(&mut self, lines: Vec<String>) {
        self.transcript = lines;
    }
}

/// The record scene's codes, sample by sample, as the QEMU board's converter produces them.
pub fn scene_codes() -> Vec<i64> {
    let mut adc = qemu_scenes::record_scene();
    let samples = (qemu_scenes::RECORD_SCENE_END_S * SAMPLE_RATE_HZ) as usize;
    (0..samples)
        .map(|_| adc.read().map_or(-1, i64::from))
        .collect()
}

/// The `method.spec` of a weighing configuration `host-sim calibrate` wrote.
pub fn method_spec(toml: &str) -> Option<String> {
    toml.lines().find_map(|line| {
        let rest = line
            .trim()
            .strip_prefix("spec")?
            .trim_start()
            .strip_prefix('=')?;
        let quoted = rest.trim().strip_prefix('"')?;
        Some(quoted.split('"').next()?.to_string())
    })
}

/// Judge the recordings in a record-scene `transcript` against the scene's `codes`: the
/// recordings, or what is wrong with them.
pub fn check_recordings(
    transcript: &[String],
    codes: &[i64],
) -> Result<Vec<ConsoleRecording>, Vec<String>> {
    let recordings = unpack(transcript.iter().map(String::as_str))
        .map_err(|error| vec![format!("the console's recordings: {error}")])?;
    let mut failures = Vec::new();
    let armed = transcript
        .iter()
        .filter(|line| line.starts_with("OK record armed"))
        .count();
    let drops = qemu_scenes::RECORD_SCENE_DROPS_S;
    if armed != drops.len() || recordings.len() != drops.len() {
        failures.push(format!(
            "{armed} recordings armed and {} written, expected {} of each",
            recordings.len(),
            drops.len()
        ));
    }
    for (index, (recording, landing_s)) in recordings.iter().zip(drops).enumerate() {
        let name = format!("recording {}", index + 1);
        if recording.samples.len() != RECORD_SAMPLES
            || recording.before != RECORD_BEFORE
            || recording.lost + recording.saturated > 0
        {
            failures.push(format!(
                "{name}: {} samples, the change at {}, {} lost, {} saturated; expected {RECORD_SAMPLES}, at {RECORD_BEFORE}, none lost or saturated",
                recording.samples.len(),
                recording.before,
                recording.lost,
                recording.saturated
            ));
            continue;
        }
        // Where the recording starts in the scene: 0.25 s before the detected landing,
        // which follows the true one within the detection's lag.
        let landing = (landing_s * SAMPLE_RATE_HZ) as usize;
        let lag = (MAX_DETECTION_LAG_S * SAMPLE_RATE_HZ) as usize;
        let recorded: Vec<i64> = recording.samples.iter().map(|s| s.unwrap_or(-1)).collect();
        let start = (landing.saturating_sub(RECORD_BEFORE)..=landing + lag - RECORD_BEFORE)
            .find(|&start| codes.get(start..start + recorded.len()) == Some(&recorded[..]));
        match start {
            Some(start) => {
                let detected = start + RECORD_BEFORE;
                if detected < landing {
                    failures.push(format!(
                        "{name}: the change detected at sample {detected}, before the landing at {landing}"
                    ));
                }
            }
            None => failures.push(format!(
                "{name}: its 5,000 codes are not the scene's from 0.25 s before a landing detected within {} ms of the drop at {landing_s} s",
                MAX_DETECTION_LAG_S * 1e3
            )),
        }
    }
    if failures.is_empty() {
        Ok(recordings)
    } else {
        Err(failures)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transcript(recordings: &[(usize, usize)], codes: &[i64]) -> Vec<String> {
        let mut lines = vec!["# fast-weighing console: type help".to_string()];
        for &(start, len) in recordings {
            lines.push("OK record armed; …".into());
            lines.push(format!(
                "RECORD begin samples={len} before={RECORD_BEFORE} rate_hz=4000"
            ));
            for (chunk, index) in codes[start..start + len].chunks(16).zip((0..).step_by(16)) {
                let words: Vec<String> = chunk.iter().map(i64::to_string).collect();
                lines.push(format!("D {index} {}", words.join(" ")));
            }
            lines.push(format!("RECORD end samples={len} lost=0 saturated=0"));
        }
        lines
    }

    /// Recordings that start 0.25 s before each landing pass; one shifted 1 s off a
    /// landing, one short, or one missing fails, naming the recording.
    #[test]
    fn recordings_must_be_the_scenes_codes_around_each_landing() {
        let codes = scene_codes();
        let at = |drop_s: f64| (drop_s * SAMPLE_RATE_HZ) as usize - RECORD_BEFORE + 10;
        let drops = qemu_scenes::RECORD_SCENE_DROPS_S;
        let good: Vec<(usize, usize)> = drops.iter().map(|&d| (at(d), RECORD_SAMPLES)).collect();
        assert_eq!(
            check_recordings(&transcript(&good, &codes), &codes).map(|r| r.len()),
            Ok(3)
        );
        let mut shifted = good.clone();
        shifted[1].0 += SAMPLE_RATE_HZ as usize;
        let failures = check_recordings(&transcript(&shifted, &codes), &codes).unwrap_err();
        assert!(failures[0].starts_with("recording 2:"), "{failures:?}");
        let mut short = good.clone();
        short[2].1 = 4_000;
        let failures = check_recordings(&transcript(&short, &codes), &codes).unwrap_err();
        assert!(failures[0].starts_with("recording 3:"), "{failures:?}");
        let failures = check_recordings(&transcript(&good[..2], &codes), &codes).unwrap_err();
        assert!(failures[0].contains("expected 3"), "{failures:?}");
    }

    #[test]
    fn the_method_spec_is_read_from_the_configuration() {
        let toml =
            "[method]\nkind = \"step\"\nspec = \"step:n=5,D=24,precision=f32\"   # the same\n";
        assert_eq!(
            method_spec(toml).as_deref(),
            Some("step:n=5,D=24,precision=f32")
        );
        assert_eq!(method_spec("[method]\nkind = \"step\"\n"), None);
    }
}
