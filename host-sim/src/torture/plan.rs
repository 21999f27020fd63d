//! One torture run as a plan: the load script the simulated cell plays, the disturbances,
//! the operator's commands and the samples the hand-off loses, all drawn from one seed.
//!
//! What a run may contain (each act is drawn with the weights in [`Plan::draw`]): loads from
//! a gram to beyond capacity placed by hand (rising over 50–300 ms, overshooting up to 10 %
//! and bouncing back over 20–60 ms), dropped from 0.5–10 mm (the impact lasting 3–10 ms) or
//! set down at once;
//! removals by hand; small additions (0.1–0.5 g) to a load that has sat for 20–60 s;
//! trickles (0.005–0.05 g/s for 5–40 s); tare and clear-tare; calibration with the right
//! reference mass or a wrong one; bursts of lost samples. Noise: white at 40–60 dB on the
//! reference step, the amplifier's own, and sometimes floor vibration, mains and a drifting
//! zero.

use crate::sensor::SensorChain;
use crate::simulated::{
    dropped_from_height, placed_by_hand, white_noise_for_snr, Disturbances, Gaussian, LoadEvent,
    Script, REFERENCE_STEP_G, SNR_WINDOW_SAMPLES,
};

/// Load events a plan may hold (a hand placement takes two).
pub const PLAN_EVENTS: usize = 48;

/// What the operator or the scene did last: each judged reading is put down to the act in
/// progress when it was shown.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ActKind {
    /// The pan empty after power-up.
    Boot,
    /// A load set down at once.
    Set,
    /// A load placed by hand: rising over 50–300 ms, overshooting and bouncing back.
    Hand,
    /// A load dropped from a height: a short impact, then the load.
    Drop,
    /// A load above the capacity.
    Overload,
    /// Everything lifted off by hand.
    Remove,
    /// A small item added to a load that has sat for a while.
    SmallAddition,
    /// A load trickling on slowly.
    Trickle,
    /// The tare taken (or cleared).
    Tare,
    /// A calibration with the right reference mass.
    Calibration,
    /// A calibration with the wrong reference mass put on.
    WrongCalibration,
    /// Samples lost in the hand-off.
    LostSamples,
}

impl ActKind {
    /// Every kind, in table order.
    pub const ALL: [ActKind; 12] = [
        ActKind::Boot,
        ActKind::Set,
        ActKind::Hand,
        ActKind::Drop,
        ActKind::Overload,
        ActKind::Remove,
        ActKind::SmallAddition,
        ActKind::Trickle,
        ActKind::Tare,
        ActKind::Calibration,
        ActKind::WrongCalibration,
        ActKind::LostSamples,
    ];

    /// The name in a trace (one word).
    pub fn key(self) -> &'static str {
        match self {
            ActKind::Boot => "boot",
            ActKind::Set => "set",
            ActKind::Hand => "hand",
            ActKind::Drop => "drop",
            ActKind::Overload => "overload",
            ActKind::Remove => "remove",
            ActKind::SmallAddition => "small_addition",
            ActKind::Trickle => "trickle",
            ActKind::Tare => "tare",
            ActKind::Calibration => "calibration",
            ActKind::WrongCalibration => "wrong_calibration",
            ActKind::LostSamples => "lost_samples",
        }
    }

    /// The name in the table.
    pub fn name(self) -> &'static str {
        match self {
            ActKind::Boot => "boot, empty pan",
            ActKind::Set => "load set down",
            ActKind::Hand => "placed by hand",
            ActKind::Drop => "dropped from a height",
            ActKind::Overload => "beyond capacity",
            ActKind::Remove => "removed by hand",
            ActKind::SmallAddition => "small addition",
            ActKind::Trickle => "trickle",
            ActKind::Tare => "tare / clear tare",
            ActKind::Calibration => "calibration, right mass",
            ActKind::WrongCalibration => "calibration, wrong mass",
            ActKind::LostSamples => "lost samples",
        }
    }
}

/// An operator command at a sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlannedCommand {
    /// Take the tare.
    Tare,
    /// Clear the tare.
    ClearTare,
    /// Start a calibration with this reference mass (the pan must be empty).
    Calibrate {
        /// The mass the operator types in, g.
        known_mass_g: f32,
    },
}

/// The instrument the plan is drawn for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instrument {
    /// Max, g.
    pub capacity_g: f64,
    /// The scale interval e, g.
    pub scale_interval_g: f64,
    /// The reference mass a calibration asks for, g.
    pub calibration_mass_g: f64,
}

/// One run, drawn from a seed.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The load the cell carries.
    pub script: Script<PLAN_EVENTS>,
    /// Noise and slow errors.
    pub disturbances: Disturbances,
    /// Operator commands, by sample, in order.
    pub commands: Vec<(u64, PlannedCommand)>,
    /// Bursts of lost samples: (first sample, count), in order.
    pub losses: Vec<(u64, u64)>,
    /// The act in progress from each sample on, in order (starts with `Boot` at 0).
    pub acts: Vec<(u64, ActKind)>,
    /// Samples in the run.
    pub samples: u64,
}

/// Draws a plan: the time, the load on the pan, and the rng.
struct Drawing<'a> {
    rate_hz: f64,
    time_s: f64,
    load_g: f64,
    rng: &'a mut Gaussian,
    events: Vec<LoadEvent>,
    commands: Vec<(u64, PlannedCommand)>,
    losses: Vec<(u64, u64)>,
    acts: Vec<(u64, ActKind)>,
}

impl Drawing<'_> {
    fn uniform(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.rng.uniform()
    }

    fn sample(&self, time_s: f64) -> u64 {
        (time_s * self.rate_hz).ceil() as u64
    }

    fn act(&mut self, kind: ActKind) {
        let sample = self.sample(self.time_s);
        self.acts.push((sample, kind));
    }

    fn wait(&mut self, seconds: f64) {
        self.time_s += seconds;
    }

    /// The load moves to `mass_g` over `ramp_s` (0: at once) from now.
    fn load(&mut self, mass_g: f64, ramp_s: f64) {
        self.events.push(LoadEvent {
            time_s: self.time_s,
            mass_g,
            ramp_s,
        });
        self.time_s += ramp_s;
        self.load_g = mass_g;
    }

    fn command(&mut self, command: PlannedCommand) {
        let sample = self.sample(self.time_s);
        self.commands.push((sample, command));
    }

    /// A mass log-uniform between 1 g and `high_g`.
    fn mass(&mut self, high_g: f64) -> f64 {
        libm::exp(self.uniform(0.0, libm::log(high_g.max(1.0))))
    }

    /// Put `added_g` more on the pan, in one of the three ways.
    fn place(&mut self, added_g: f64, kind: ActKind) {
        let target = self.load_g + added_g;
        let events = match kind {
            ActKind::Hand => {
                let rise = self.uniform(0.05, 0.3);
                let overshoot = self.uniform(0.0, 0.1);
                let back = self.uniform(0.02, 0.06);
                placed_by_hand(self.time_s, self.load_g, target, rise, overshoot, back)
            }
            ActKind::Drop | ActKind::Overload => {
                let height_m = self.uniform(0.5e-3, 10e-3);
                let contact_s = self.uniform(0.003, 0.01);
                dropped_from_height(self.time_s, self.load_g, target, height_m, contact_s)
            }
            _ => {
                self.load(target, 0.0);
                return;
            }
        };
        for event in events {
            self.events.push(event);
            self.time_s = event.time_s + event.ramp_s;
        }
        self.load_g = target;
    }
}

impl Plan {
    /// The plan of one run from `seed`, on `chain` (its sample rate and the SNR's step),
    /// for `instrument`.
    ///
    /// Weights of the acts, while the events last: a load placed (by hand 30 %, dropped 20
    /// %, set down 15 %, beyond capacity 5 %) when the pan holds less than 80 % of Max,
    /// else removed; removal 12 %; small addition 5 %; trickle 5 %; tare or clear tare 4
    /// %; calibration (the pan emptied first) 4 %, a fifth of them with a wrong mass; a
    /// burst of lost samples 5 % (on top, at any time).
    pub fn draw(seed: u64, chain: &SensorChain, instrument: Instrument) -> Self {
        let mut rng = Gaussian::new(seed);
        let rate_hz = 1.0 / chain.conversion_period_s();
        let disturbances = draw_disturbances(&mut rng, chain, instrument.scale_interval_g);
        let mut d = Drawing {
            rate_hz,
            time_s: 0.0,
            load_g: 0.0,
            rng: &mut rng,
            events: Vec::new(),
            commands: Vec::new(),
            losses: Vec::new(),
            acts: vec![(0, ActKind::Boot)],
        };
        let boot = d.uniform(0.3, 3.0);
        d.wait(boot);
        let max = instrument.capacity_g;
        let acts = 3 + (d.uniform(0.0, 6.0) as usize);
        for _ in 0..acts {
            if d.events.len() + 6 > PLAN_EVENTS {
                break;
            }
            let pick = d.uniform(0.0, 1.0);
            if pick < 0.70 && d.load_g < 0.8 * max {
                let how = d.uniform(0.0, 0.70);
                let kind = match how {
                    x if x < 0.30 => ActKind::Hand,
                    x if x < 0.50 => ActKind::Drop,
                    x if x < 0.65 => ActKind::Set,
                    _ => ActKind::Overload,
                };
                let added = if kind == ActKind::Overload {
                    max * d.uniform(1.0, 1.5) - d.load_g
                } else {
                    d.mass(0.8 * max - d.load_g)
                };
                d.act(kind);
                d.place(added, kind);
            } else if pick < 0.82 {
                d.act(ActKind::Remove);
                let lift = d.uniform(0.1, 0.3);
                d.load(0.0, lift);
            } else if pick < 0.87 && d.load_g > 0.0 {
                let sit = d.uniform(20.0, 60.0);
                d.wait(sit);
                d.act(ActKind::SmallAddition);
                let small = d.uniform(0.1, 0.5);
                d.place(small, ActKind::Set);
            } else if pick < 0.92 {
                d.act(ActKind::Trickle);
                let rate = d.uniform(0.005, 0.05);
                let duration = d.uniform(5.0, 40.0);
                let target = d.load_g + rate * duration;
                d.load(target, duration);
            } else if pick < 0.96 {
                d.act(ActKind::Tare);
                let clear = d.uniform(0.0, 1.0) < 0.3;
                d.command(if clear {
                    PlannedCommand::ClearTare
                } else {
                    PlannedCommand::Tare
                });
            } else {
                calibrate(&mut d, instrument);
            }
            let settle = d.uniform(0.5, 8.0);
            d.wait(settle);
            if d.uniform(0.0, 1.0) < 0.05 {
                let at = d.time_s - d.uniform(0.0, settle);
                let sample = d.sample(at);
                let count = 1 + d.uniform(0.0, 50.0) as u64;
                d.acts.push((sample, ActKind::LostSamples));
                d.losses.push((sample, count));
            }
        }
        d.wait(2.0);
        let end_s = d.time_s;
        let mut script = Script::new(end_s);
        for event in &d.events {
            // In time order within the scene by construction; a full script stops adding.
            let _ = script.push(*event);
        }
        let mut acts = d.acts;
        acts.sort_by_key(|(sample, _)| *sample);
        let mut losses = d.losses;
        losses.sort_by_key(|(sample, _)| *sample);
        Self {
            script,
            disturbances,
            commands: d.commands,
            losses,
            acts,
            samples: (end_s * rate_hz) as u64,
        }
    }
}

/// Empty the pan, start a calibration, put the reference mass on (or a wrong one), leave
/// it, lift it off.
fn calibrate(d: &mut Drawing<'_>, instrument: Instrument) {
    if d.load_g != 0.0 {
        d.act(ActKind::Remove);
        d.load(0.0, 0.2);
        d.wait(3.0);
    }
    let wrong = d.uniform(0.0, 1.0) < 0.2;
    let known = instrument.calibration_mass_g;
    let placed = if wrong {
        known * [0.7, 1.25, 1.45][(d.uniform(0.0, 3.0) as usize).min(2)]
    } else {
        known
    };
    d.act(if wrong {
        ActKind::WrongCalibration
    } else {
        ActKind::Calibration
    });
    d.command(PlannedCommand::Calibrate {
        known_mass_g: known as f32,
    });
    d.wait(1.0);
    d.place(placed, ActKind::Hand);
    d.wait(4.0);
    d.load(0.0, 0.2);
}

/// The fastest zero drift a run may have, in scale intervals per second: OIML R 76 lets
/// the zero of a class III instrument move 1 e per 5 °C (R 76-1 3.9.2.3, temperature
/// effect on the no-load indication); a room swinging 10 °C in 10 minutes moves it 2 e in 600 s.
pub const ZERO_DRIFT_LIMIT_E_PER_S: f64 = 2.0 / 600.0;

/// White noise at 40–60 dB on the reference step with the amplifier's own; floor
/// vibration (0.05–0.5 g RMS at 10–40 Hz) in three runs of ten; mains (0.05–0.3 g) in
/// three of ten; a zero drifting (either way, up to [`ZERO_DRIFT_LIMIT_E_PER_S`]) in three
/// of ten. The drift is the instrument's, not the load's: the truth does not move with it,
/// so a drift the scale does not track away counts as error.
fn draw_disturbances(rng: &mut Gaussian, chain: &SensorChain, e_g: f64) -> Disturbances {
    let snr_db = 40.0 + 20.0 * rng.uniform();
    let mut disturbances = Disturbances::white(white_noise_for_snr(
        chain,
        REFERENCE_STEP_G,
        snr_db,
        SNR_WINDOW_SAMPLES,
    ));
    disturbances.amplifier_noise = true;
    if rng.uniform() < 0.3 {
        disturbances.vibration_rms_g = 0.05 + 0.45 * rng.uniform();
        disturbances.vibration_hz = 10.0 + 30.0 * rng.uniform();
        disturbances.vibration_bandwidth_hz = 2.0;
    }
    if rng.uniform() < 0.3 {
        disturbances.mains_amplitude_g = 0.05 + 0.25 * rng.uniform();
    }
    if rng.uniform() < 0.3 {
        disturbances.drift_g_per_s = (2.0 * rng.uniform() - 1.0) * ZERO_DRIFT_LIMIT_E_PER_S * e_g;
    }
    disturbances
}
