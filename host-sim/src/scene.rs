//! Scenes as small TOML files: only what a scene needs, defaults for the rest, so a study or
//! a test names its conditions in a file anyone can read. A bad key must never be taken
//! silently: every value is checked and an error names the file, the key and what was
//! expected.
//!
//! ```toml
//! description = "138.32 g dropped on the empty platform"
//! duration_s = 1.5            # default 1.5
//! [[events]]                  # in time order; a step unless ramp_s > 0
//! time_s = 0.0
//! mass_g = 138.32
//! [noise]                     # every key optional
//! snr_db = 50.0               # white noise, thesis eq. 4.39, relative to the first step
//! vibration_rms_g = 0.0       # narrow-band force disturbance near the resonance
//! mains_amplitude_g = 0.0     # 50 Hz pickup
//! drift_g_per_s = 0.0         # zero drift
//! creep_fraction = 0.0        # creep towards (1 + fraction)·load ...
//! creep_time_constant_s = 60  # ... with this time constant
//! [adc]
//! bits = 16                   # 12 or 16
//! [cell]                      # every key optional: the reference cell
//! ring_hz = 25.0              # natural frequency carrying design_load_g
//! damping_ratio = 0.03
//! design_load_g = 138.32
//! platform_mass_kg = 0.120
//! capacity_g = 600.0          # Max, with the rated output at it
//! rated_output_mv_per_v = 2.0
//! creep_fraction = 0.0        # creep (here or in [noise], not both)
//! creep_time_constant_s = 60
//! ```
//!
//! An event's load may arrive three ways: `how = "step"` (default; a ramp when `ramp_s` >
//! 0), `how = "hand"` (rising over `rise_s`, overshooting by `overshoot` of the change,
//! back over `bounce_s`) or `how = "drop"` (from `height_mm`, the impact lasting
//! `contact_ms`).

mod shipped;

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Deserialize;

pub use shipped::{shipped_names, shipped_scene, SHIPPED_SCENES};

use crate::sensor::{Adc, Ina114, LoadCell, SensorChain, SAMPLE_RATE_HZ};
use crate::simulated::{
    dropped_from_height, placed_by_hand, white_noise_for_snr, Disturbances, LoadEvent, Script,
    SimulatedAdc, SNR_WINDOW_SAMPLES,
};

/// The most events a scene file may hold.
pub const MAX_EVENTS: usize = 64;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct EventFile {
    time_s: f64,
    mass_g: f64,
    #[serde(default)]
    ramp_s: f64,
    /// `step` (default; a ramp when `ramp_s` > 0), `hand` or `drop`.
    #[serde(default)]
    how: Placement,
    /// `hand`: the rise, s (default 0.15).
    rise_s: Option<f64>,
    /// `hand`: the overshoot, a fraction of the change (default 0.05).
    overshoot: Option<f64>,
    /// `hand`: back from the overshoot to the load, s (default 0.04).
    bounce_s: Option<f64>,
    /// `drop`: the height the item falls from, mm (default 10).
    height_mm: Option<f64>,
    /// `drop`: how long the impact lasts, ms (default 5).
    contact_ms: Option<f64>,
}

/// How an event's load arrives.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
enum Placement {
    /// At once (or along `ramp_s`).
    #[default]
    Step,
    /// By hand: rising, overshooting, bouncing back.
    Hand,
    /// Dropped from a height: an impact, then the load.
    Drop,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct NoiseFile {
    snr_db: Option<f64>,
    snr_step_g: Option<f64>,
    amplifier: bool,
    vibration_rms_g: f64,
    vibration_hz: f64,
    vibration_bandwidth_hz: f64,
    mains_amplitude_g: f64,
    mains_hz: f64,
    drift_g_per_s: f64,
    creep_fraction: f64,
    creep_time_constant_s: f64,
}

impl Default for NoiseFile {
    fn default() -> Self {
        let none = Disturbances::none();
        Self {
            snr_db: Some(50.0),
            snr_step_g: None,
            amplifier: true,
            vibration_rms_g: 0.0,
            vibration_hz: none.vibration_hz,
            vibration_bandwidth_hz: none.vibration_bandwidth_hz,
            mains_amplitude_g: 0.0,
            mains_hz: none.mains_hz,
            drift_g_per_s: 0.0,
            creep_fraction: 0.0,
            creep_time_constant_s: none.creep_time_constant_s,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct AdcFile {
    bits: u32,
    reference_v: f64,
    oversampling: u16,
}

impl Default for AdcFile {
    fn default() -> Self {
        let adc = Adc::reference();
        Self {
            bits: adc.bits,
            reference_v: adc.reference_v,
            oversampling: adc.oversampling,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct CellFile {
    platform_mass_kg: f64,
    design_load_g: f64,
    ring_hz: f64,
    damping_ratio: f64,
    capacity_g: f64,
    rated_output_mv_per_v: f64,
    creep_fraction: Option<f64>,
    creep_time_constant_s: Option<f64>,
}

impl Default for CellFile {
    fn default() -> Self {
        let reference = LoadCell::reference();
        Self {
            platform_mass_kg: 0.120,
            design_load_g: 138.32,
            ring_hz: 25.0,
            damping_ratio: 0.03,
            capacity_g: reference.capacity_g,
            rated_output_mv_per_v: reference.rated_output_mv_per_v,
            creep_fraction: None,
            creep_time_constant_s: None,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    #[serde(default)]
    description: String,
    #[serde(default = "default_duration")]
    duration_s: f64,
    #[serde(default = "default_cutoff")]
    filter_cutoff_hz: f64,
    events: Vec<EventFile>,
    #[serde(default)]
    noise: NoiseFile,
    #[serde(default)]
    adc: AdcFile,
    #[serde(default)]
    cell: CellFile,
}

fn default_duration() -> f64 {
    1.5
}

fn default_cutoff() -> f64 {
    100.0
}

/// A scene ready to simulate.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The scene's name (its file stem).
    pub name: String,
    /// What the scene shows.
    pub description: String,
    /// The sensor chain.
    pub chain: SensorChain,
    /// The load events.
    pub script: Script<MAX_EVENTS>,
    /// The noises, white noise resolved from the SNR.
    pub disturbances: Disturbances,
    /// The SNR the white noise was set from, dB (None: no white noise).
    pub snr_db: Option<f64>,
    /// The step the SNR refers to, g.
    pub snr_step_g: f64,
}

fn check(
    file: &Path,
    key: &str,
    ok: bool,
    expected: &str,
    found: impl std::fmt::Display,
) -> Result<()> {
    if !ok {
        bail!(
            "scene file {}: key `{key}`: expected {expected}, found {found}",
            file.display()
        );
    }
    Ok(())
}

fn finite_positive(value: f64) -> bool {
    value.is_finite() && value > 0.0
}

/// The top-level keys: the duration and the anti-alias filter's cut-off.
fn check_top_level(file: &Path, raw: &SceneFile) -> Result<()> {
    check(
        file,
        "duration_s",
        finite_positive(raw.duration_s),
        "a positive number of seconds",
        raw.duration_s,
    )?;
    check(
        file,
        "filter_cutoff_hz",
        finite_positive(raw.filter_cutoff_hz) && raw.filter_cutoff_hz < SAMPLE_RATE_HZ / 2.0,
        "a cut-off between 0 and 2000 Hz",
        raw.filter_cutoff_hz,
    )
}

/// The `[adc]` section.
fn adc_of(file: &Path, adc: &AdcFile) -> Result<Adc> {
    check(
        file,
        "adc.bits",
        adc.bits == 12 || adc.bits == 16,
        "12 or 16",
        adc.bits,
    )?;
    check(
        file,
        "adc.reference_v",
        finite_positive(adc.reference_v),
        "a positive voltage",
        adc.reference_v,
    )?;
    check(
        file,
        "adc.oversampling",
        (1..=256).contains(&adc.oversampling),
        "1..=256",
        adc.oversampling,
    )?;
    Ok(Adc {
        bits: adc.bits,
        reference_v: adc.reference_v,
        oversampling: adc.oversampling,
    })
}

/// The `[cell]` section: a cell designed to ring at `ring_hz` (its natural frequency) with
/// the design load, of `capacity_g` at `rated_output_mv_per_v` (the reference cell's unless
/// given).
fn cell_of(file: &Path, c: &CellFile) -> Result<LoadCell> {
    check(
        file,
        "cell.capacity_g",
        finite_positive(c.capacity_g),
        "a positive capacity in grams",
        c.capacity_g,
    )?;
    check(
        file,
        "cell.rated_output_mv_per_v",
        finite_positive(c.rated_output_mv_per_v),
        "a positive rated output in mV/V",
        c.rated_output_mv_per_v,
    )?;
    check(
        file,
        "cell.platform_mass_kg",
        finite_positive(c.platform_mass_kg),
        "a positive mass in kg",
        c.platform_mass_kg,
    )?;
    check(
        file,
        "cell.ring_hz",
        finite_positive(c.ring_hz),
        "a positive frequency",
        c.ring_hz,
    )?;
    check(
        file,
        "cell.damping_ratio",
        c.damping_ratio.is_finite() && c.damping_ratio > 0.0 && c.damping_ratio < 1.0,
        "a damping ratio in (0, 1)",
        c.damping_ratio,
    )?;
    let mut cell = LoadCell::designed(
        c.platform_mass_kg,
        c.design_load_g,
        c.ring_hz,
        c.damping_ratio,
    );
    cell.capacity_g = c.capacity_g;
    cell.rated_output_mv_per_v = c.rated_output_mv_per_v;
    Ok(cell)
}

/// The cell's creep (`cell.creep_fraction`, `cell.creep_time_constant_s`): a property of the
/// cell, so it belongs in `[cell]`; `[noise]` keeps its keys for older scenes, and a scene
/// may give it in one place only.
fn creep_of(
    file: &Path,
    c: &CellFile,
    n: &NoiseFile,
    disturbances: &mut Disturbances,
) -> Result<()> {
    if c.creep_fraction.is_none() && c.creep_time_constant_s.is_none() {
        return Ok(());
    }
    let noise_default = NoiseFile::default();
    check(
        file,
        "cell.creep_fraction",
        n.creep_fraction == noise_default.creep_fraction
            && n.creep_time_constant_s == noise_default.creep_time_constant_s,
        "creep in [cell] or in [noise], not both",
        "both",
    )?;
    let fraction = c.creep_fraction.unwrap_or(0.0);
    let time_constant = c
        .creep_time_constant_s
        .unwrap_or(noise_default.creep_time_constant_s);
    check(
        file,
        "cell.creep_fraction",
        fraction.is_finite() && fraction.abs() < 0.1,
        "a fraction of the load below 0.1 in size",
        fraction,
    )?;
    check(
        file,
        "cell.creep_time_constant_s",
        finite_positive(time_constant),
        "a positive time constant in seconds",
        time_constant,
    )?;
    disturbances.creep_fraction = fraction;
    disturbances.creep_time_constant_s = time_constant;
    Ok(())
}

/// At least one `[[events]]` entry, and no more than a script holds.
fn check_event_count(file: &Path, events: &[EventFile]) -> Result<()> {
    check(
        file,
        "events",
        !events.is_empty(),
        "at least one [[events]] entry",
        "none",
    )?;
    check(
        file,
        "events",
        events.len() <= MAX_EVENTS,
        "at most 64 events",
        events.len(),
    )
}

/// The `[[events]]` entries as a script: masses within the cell's capacity, in time order.
fn script_of(
    file: &Path,
    events: &[EventFile],
    duration_s: f64,
    capacity_g: f64,
) -> Result<Script<MAX_EVENTS>> {
    let mut script = Script::new(duration_s);
    let mut previous_g = 0.0;
    for (index, event) in events.iter().enumerate() {
        let key = format!("events[{index}]");
        // Up to 1.5 Max: a scene may overload the cell.
        check(
            file,
            &format!("{key}.mass_g"),
            event.mass_g.is_finite() && (0.0..=1.5 * capacity_g).contains(&event.mass_g),
            &format!(
                "a mass in 0..={} g (1.5 times the cell's capacity)",
                1.5 * capacity_g
            ),
            event.mass_g,
        )?;
        for load in placement_events(file, &key, event, previous_g)? {
            push_event(file, &key, &mut script, load, duration_s)?;
        }
        previous_g = event.mass_g;
    }
    Ok(script)
}

/// The load events of one `[[events]]` entry: one for a step or ramp, two for a placement
/// by hand or a drop from a height (see `simulated::placed_by_hand`, `dropped_from_height`).
fn placement_events(
    file: &Path,
    key: &str,
    event: &EventFile,
    previous_g: f64,
) -> Result<Vec<LoadEvent>> {
    let option = |name: &str, value: Option<f64>, default: f64, ok: fn(f64) -> bool| {
        let value = value.unwrap_or(default);
        check(
            file,
            &format!("{key}.{name}"),
            ok(value),
            "a finite, non-negative number (positive for a duration)",
            value,
        )
        .map(|()| value)
    };
    let hand_keys = event.rise_s.is_some() || event.overshoot.is_some() || event.bounce_s.is_some();
    let drop_keys = event.height_mm.is_some() || event.contact_ms.is_some();
    check(
        file,
        &format!("{key}.how"),
        (event.how == Placement::Hand || !hand_keys) && (event.how == Placement::Drop || !drop_keys),
        "`how = \"hand\"` with rise_s/overshoot/bounce_s, `how = \"drop\"` with height_mm/contact_ms",
        format!("{:?}", event.how).to_lowercase(),
    )?;
    let non_negative = |v: f64| v.is_finite() && v >= 0.0;
    Ok(match event.how {
        Placement::Step => vec![LoadEvent {
            time_s: event.time_s,
            mass_g: event.mass_g,
            ramp_s: event.ramp_s,
        }],
        Placement::Hand => {
            let rise = option("rise_s", event.rise_s, 0.15, finite_positive)?;
            let overshoot = option("overshoot", event.overshoot, 0.05, non_negative)?;
            let bounce = option("bounce_s", event.bounce_s, 0.04, finite_positive)?;
            placed_by_hand(
                event.time_s,
                previous_g,
                event.mass_g,
                rise,
                overshoot,
                bounce,
            )
            .to_vec()
        }
        Placement::Drop => {
            let height = option("height_mm", event.height_mm, 10.0, non_negative)?;
            let contact = option("contact_ms", event.contact_ms, 5.0, finite_positive)?;
            dropped_from_height(
                event.time_s,
                previous_g,
                event.mass_g,
                height * 1e-3,
                contact * 1e-3,
            )
            .to_vec()
        }
    })
}

/// Add one load event of `[[events]]` entry `key` to the script.
fn push_event(
    file: &Path,
    key: &str,
    script: &mut Script<MAX_EVENTS>,
    event: LoadEvent,
    duration_s: f64,
) -> Result<()> {
    {
        script
            .push(event)
            .map_err(|error| {
                anyhow::anyhow!(
                    "scene file {}: key `{key}.time_s`: expected a time after the previous event ends and within duration_s = {}, found {} ({error:?})",
                    file.display(),
                    duration_s,
                    event.time_s
                )
            })?;
    }
    Ok(())
}

/// The `[noise]` section, the white noise resolved from its SNR on `snr_step_g`.
fn disturbances_of(
    file: &Path,
    n: &NoiseFile,
    chain: &SensorChain,
    snr_step_g: f64,
) -> Result<Disturbances> {
    check(
        file,
        "noise.snr_step_g",
        finite_positive(snr_step_g),
        "a positive step in grams",
        snr_step_g,
    )?;
    for (key, value) in [
        ("noise.vibration_rms_g", n.vibration_rms_g),
        ("noise.mains_amplitude_g", n.mains_amplitude_g),
        ("noise.creep_fraction", n.creep_fraction.abs()),
    ] {
        check(
            file,
            key,
            value.is_finite() && value >= 0.0,
            "a finite, non-negative number",
            value,
        )?;
    }
    let white_noise_g = match n.snr_db {
        Some(snr) => {
            check(
                file,
                "noise.snr_db",
                snr.is_finite(),
                "a finite SNR in dB",
                snr,
            )?;
            white_noise_for_snr(chain, snr_step_g, snr, SNR_WINDOW_SAMPLES)
        }
        None => 0.0,
    };
    Ok(Disturbances {
        white_noise_g,
        amplifier_noise: n.amplifier,
        vibration_rms_g: n.vibration_rms_g,
        vibration_hz: n.vibration_hz,
        vibration_bandwidth_hz: n.vibration_bandwidth_hz,
        mains_amplitude_g: n.mains_amplitude_g,
        mains_hz: n.mains_hz,
        drift_g_per_s: n.drift_g_per_s,
        creep_fraction: n.creep_fraction,
        creep_time_constant_s: n.creep_time_constant_s,
    })
}

impl Scene {
    /// Load a scene: a file on disk as given, else the shipped scene of that name (built
    /// into the binary, so a copied binary needs no source tree).
    pub fn load(scene: &str) -> Result<Self> {
        let path = Path::new(scene);
        if !path.exists() {
            match shipped_scene(scene) {
                Some(text) => return Self::parse(Path::new(&format!("{scene}.toml")), text),
                None => bail!(
                    "no scene file {scene} and no shipped scene of that name (shipped: {})",
                    shipped_names().join(", ")
                ),
            }
        }
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read scene file {}", path.display()))?;
        Self::parse(path, &text)
    }

    /// Parse the text of a scene file; `file` names it in errors. The sections are checked
    /// in file order (top-level keys, `[adc]`, `[cell]`, `[[events]]`, `[noise]`), so the first
    /// bad key is the one reported.
    pub fn parse(file: &Path, text: &str) -> Result<Self> {
        let raw: SceneFile = toml::from_str(text)
            .map_err(|error| anyhow::anyhow!("scene file {}: {error}", file.display()))?;
        check_top_level(file, &raw)?;
        let adc = adc_of(file, &raw.adc)?;
        let cell = cell_of(file, &raw.cell)?;
        check_event_count(file, &raw.events)?;
        let chain = SensorChain {
            cell,
            amplifier: Ina114::reference(),
            filter_cutoff_hz: raw.filter_cutoff_hz,
            adc,
            sample_rate_hz: SAMPLE_RATE_HZ,
        };
        let script = script_of(file, &raw.events, raw.duration_s, cell.capacity_g)?;
        let snr_step_g = raw.noise.snr_step_g.unwrap_or(raw.events[0].mass_g.abs());
        let mut disturbances = disturbances_of(file, &raw.noise, &chain, snr_step_g)?;
        creep_of(file, &raw.cell, &raw.noise, &mut disturbances)?;
        Ok(Self {
            name: file
                .file_stem()
                .map(|stem| stem.to_string_lossy().into_owned())
                .unwrap_or_default(),
            description: raw.description,
            chain,
            script,
            disturbances,
            snr_db: raw.noise.snr_db,
            snr_step_g,
        })
    }

    /// The same scene with white noise at another SNR (relative to the same step).
    pub fn with_snr_db(&self, snr_db: f64) -> Self {
        let mut scene = self.clone();
        scene.snr_db = Some(snr_db);
        scene.disturbances.white_noise_g =
            white_noise_for_snr(&self.chain, self.snr_step_g, snr_db, SNR_WINDOW_SAMPLES);
        scene
    }

    /// The same scene with `seconds` of empty pan before it (its noise running): a study
    /// that starts at a load's landing then sees the noise as a pan that stood before it
    /// does, not starting with the load. `None` if the script cannot be shifted.
    pub fn delayed(&self, seconds: f64) -> Option<Self> {
        let mut script = Script::new(self.script.end_s() + seconds);
        for event in self.script.events() {
            script
                .push(LoadEvent {
                    time_s: event.time_s + seconds,
                    ..*event
                })
                .ok()?;
        }
        Some(Self {
            script,
            ..self.clone()
        })
    }

    /// The empty pan with this scene's chain and noise, for `seconds`.
    pub fn empty_pan(&self, seconds: f64) -> Self {
        Self {
            script: Script::new(seconds),
            ..self.clone()
        }
    }

    /// A simulated ADC playing this scene.
    pub fn adc(&self, seed: u64) -> SimulatedAdc<MAX_EVENTS> {
        SimulatedAdc::new(self.chain, self.script, self.disturbances, seed)
    }

    /// Number of output samples in the scene.
    pub fn samples(&self) -> usize {
        (self.script.end_s() * self.chain.sample_rate_hz).round() as usize
    }

    /// The first event: the step a study estimates. Returns (onset sample, step in grams,
    /// load before it).
    pub fn studied_step(&self) -> (usize, f64, f64) {
        let events = self.script.events();
        let first = events[0];
        let onset = (first.time_s * self.chain.sample_rate_hz - 1e-9)
            .ceil()
            .max(0.0) as usize;
        (onset, first.mass_g, 0.0)
    }

    /// Samples from the studied step's onset to the next event or the end of the scene.
    pub fn studied_window(&self) -> usize {
        let (onset, _, _) = self.studied_step();
        let end_s = self
            .script
            .events()
            .get(1)
            .map(|event| event.time_s)
            .unwrap_or(self.script.end_s());
        ((end_s * self.chain.sample_rate_hz).round() as usize).saturating_sub(onset)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error_of(text: &str) -> String {
        format!(
            "{:#}",
            Scene::parse(Path::new("bad.toml"), text).unwrap_err()
        )
    }

    #[test]
    fn shipped_scenes_parse() {
        assert!(SHIPPED_SCENES.len() >= 11);
        for (name, _) in SHIPPED_SCENES {
            let scene = Scene::load(name).unwrap_or_else(|e| panic!("{name}: {e:#}"));
            assert_eq!(scene.name, *name);
            assert!(scene.samples() > 0, "{name}");
        }
    }

    #[test]
    fn placements_expand_into_load_events_and_refuse_keys_of_another_kind() {
        let scene = Scene::parse(
            Path::new("p.toml"),
            "duration_s = 3.0\n[[events]]\ntime_s = 0.5\nmass_g = 100.0\nhow = \"hand\"\nrise_s = 0.2\novershoot = 0.1\n\
             [[events]]\ntime_s = 1.5\nmass_g = 150.0\nhow = \"drop\"\nheight_mm = 10.0\ncontact_ms = 5.0\n",
        )
        .unwrap();
        let events = scene.script.events();
        assert_eq!(events.len(), 4);
        // By hand: up to 110 g over 0.2 s, back to 100 g over the default 40 ms.
        assert_eq!((events[0].mass_g, events[0].ramp_s), (110.0, 0.2));
        assert_eq!(
            (events[1].time_s, events[1].mass_g, events[1].ramp_s),
            (0.7, 100.0, 0.04)
        );
        // Dropped: 50 g with the momentum of a 10 mm fall over 5 ms, then 150 g.
        let impact = events[2].mass_g - 150.0;
        assert!((impact * 0.005 - 50.0 * (2.0 * 9.80665f64 * 0.01).sqrt() / 9.80665).abs() < 1e-9);
        assert_eq!((events[3].time_s, events[3].mass_g), (1.505, 150.0));
        let message = error_of("[[events]]\ntime_s = 0.0\nmass_g = 1.0\nheight_mm = 3.0\n");
        assert!(message.contains("`events[0].how`"), "{message}");
        let message =
            error_of("[[events]]\ntime_s = 0.0\nmass_g = 1.0\nhow = \"hand\"\nrise_s = -1.0\n");
        assert!(message.contains("`events[0].rise_s`"), "{message}");
        let message = error_of("[[events]]\ntime_s = 0.0\nmass_g = 1.0\nhow = \"throw\"\n");
        assert!(
            message.contains("throw") && message.contains("hand"),
            "{message}"
        );
    }

    #[test]
    fn the_cell_section_sets_capacity_rated_output_and_creep() {
        let scene = Scene::load("small-cell").unwrap();
        let reference = SensorChain::reference();
        // 1 mV/V over 100 g against 2 mV/V over 600 g: three times the sensitivity.
        let ratio = scene.chain.counts_per_gram() / reference.counts_per_gram();
        assert!((ratio - 3.0).abs() < 1e-9, "{ratio}");
        assert_eq!(scene.disturbances.creep_fraction, 0.0003);
        assert_eq!(scene.disturbances.creep_time_constant_s, 30.0);
        // 40 Hz with its design load of 50 g.
        let hz = scene.chain.cell.natural_frequency_rad_s(50.0) / (2.0 * std::f64::consts::PI);
        assert!((hz - 40.0).abs() < 1e-9, "{hz}");
        // Beyond 1.5 Max, and creep in two places, are refused.
        let message =
            error_of("[cell]\ncapacity_g = 100.0\n[[events]]\ntime_s = 0.0\nmass_g = 160.0\n");
        assert!(
            message.contains("`events[0].mass_g`") && message.contains("150 g"),
            "{message}"
        );
        let message = error_of(
            "[cell]\ncreep_fraction = 0.001\n[noise]\ncreep_fraction = 0.001\n[[events]]\ntime_s = 0.0\nmass_g = 1.0\n",
        );
        assert!(message.contains("not both"), "{message}");
    }

    #[test]
    fn minimal_scene_takes_the_defaults() {
        let scene = Scene::parse(
            Path::new("m.toml"),
            "[[events]]\ntime_s = 0.0\nmass_g = 138.32\n",
        )
        .unwrap();
        assert_eq!(scene.chain, SensorChain::reference());
        assert_eq!(scene.snr_db, Some(50.0));
        assert_eq!(scene.samples(), 6000);
    }

    #[test]
    fn wrong_type_names_file_key_and_expectation() {
        let message =
            error_of("[[events]]\ntime_s = 0.0\nmass_g = 1.0\n[noise]\nsnr_db = \"high\"\n");
        assert!(message.contains("bad.toml"), "{message}");
        assert!(message.contains("snr_db"), "{message}");
        assert!(
            message.contains("expected f64") || message.contains("expected a"),
            "{message}"
        );
    }

    #[test]
    fn unknown_key_is_named_with_the_expected_ones() {
        let message = error_of("[[events]]\ntime_s = 0.0\nmass_g = 1.0\n[adc]\nbitz = 12\n");
        assert!(
            message.contains("bad.toml") && message.contains("bitz"),
            "{message}"
        );
        assert!(
            message.contains("expected one of") && message.contains("bits"),
            "{message}"
        );
    }

    #[test]
    fn bad_values_name_the_key() {
        let message = error_of("[[events]]\ntime_s = 0.0\nmass_g = 1.0\n[adc]\nbits = 14\n");
        assert!(
            message.contains("bad.toml")
                && message.contains("`adc.bits`")
                && message.contains("expected 12 or 16"),
            "{message}"
        );
        let message = error_of(
            "[[events]]\ntime_s = 0.5\nmass_g = 1.0\n[[events]]\ntime_s = 0.2\nmass_g = 0.0\n",
        );
        assert!(message.contains("`events[1].time_s`"), "{message}");
        let message = error_of("duration_s = 1.0\n");
        assert!(
            message.contains("bad.toml") && message.contains("events"),
            "{message}"
        );
    }
}
