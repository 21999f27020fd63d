//! Whether a reading the scale shows is right: the maximum permissible error, the truth a
//! display may lag behind, and the tally per act.

use std::collections::BTreeMap;

use super::plan::ActKind;

/// The error limits a shown reading is judged against.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Max, g.
    pub capacity_g: f64,
    /// The scale interval e, g.
    pub scale_interval_g: f64,
    /// The configured accuracy target, relative to the load (the weighing configuration's
    /// `target_relative`).
    pub target_relative: f64,
    /// The load the target was set at (the calibration mass), g: below it the target is
    /// `target_relative` of this mass.
    pub target_mass_g: f64,
}

impl Limits {
    /// The maximum permissible error for a net load of `load_g` (OIML R 76-1, class III,
    /// initial verification): 0.5 e up to 500 e, 1 e up to 2,000 e, 1.5 e above.
    pub fn mpe_class_iii_g(&self, load_g: f64) -> f64 {
        let e = self.scale_interval_g;
        let intervals = load_g.abs() / e;
        if intervals <= 500.0 {
            0.5 * e
        } else if intervals <= 2000.0 {
            e
        } else {
            1.5 * e
        }
    }

    /// The error a reading of `load_g` may have: the MPE, or the configured target where
    /// it is tighter (`target_relative` of the load, or of the target's mass below it).
    pub fn permissible_g(&self, load_g: f64) -> f64 {
        let target = self.target_relative * load_g.abs().max(self.target_mass_g);
        self.mpe_class_iii_g(load_g).min(target)
    }

    /// Above this gross load the scale must not show a mass (Max + 9 e, OIML R 76).
    pub fn overload_g(&self) -> f64 {
        self.capacity_g + 9.0 * self.scale_interval_g
    }
}

/// What was on the pan over the last readout period (a display may lag one period): the
/// least and greatest true net load in it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Truth {
    /// Least true net load, g.
    pub low_g: f64,
    /// Greatest true net load, g.
    pub high_g: f64,
    /// Least true gross load, g: above Max + 9 e over the whole period, no mass may be
    /// shown settled.
    pub gross_low_g: f64,
}

impl Truth {
    /// How far `shown_g` lies outside the interval, g (0 inside).
    pub fn error_g(&self, shown_g: f64) -> f64 {
        if shown_g < self.low_g {
            self.low_g - shown_g
        } else if shown_g > self.high_g {
            shown_g - self.high_g
        } else {
            0.0
        }
    }
}

/// A wrong reading shown as settled, to reproduce.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wrong {
    /// The run (its seed is `run_seed(seed, run)`).
    pub run: u64,
    /// When, s.
    pub time_s: f64,
    /// The act in progress.
    pub act: ActKind,
    /// What the scale showed, g.
    pub shown_g: f64,
    /// The true net load over the period before the line, g: least and greatest.
    pub truth_g: (f64, f64),
    /// How far the shown mass lies outside that range, g (infinite: a mass shown settled
    /// above Max + 9 e).
    pub error_g: f64,
    /// The permissible error, g.
    pub permissible_g: f64,
    /// The state shown.
    pub state: &'static str,
    /// How long the loads on the pan had spanned no more than the permissible error, s.
    pub steady_s: f64,
    /// What the data held against the reading at its line ([`Evidence::z`]).
    pub evidence_z: f64,
    /// How finely one readout line's data resolved the permissible error on that pan
    /// ([`Line::resolution`]); `None` before the pan had shown its scatter.
    pub resolution: Option<f64>,
}

/// Counts for one act.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Tally {
    /// Readout lines judged.
    pub readings: u64,
    /// Lines shown stable (or empty, or final) with a mass: the display says "this is it".
    pub shown: u64,
    /// Of those, outside the permissible error (or a mass shown above Max + 9 e).
    pub silent_wrong: u64,
    /// Lines with a mass outside the permissible error but flagged as not settled
    /// (estimating).
    pub flagged_wrong: u64,
    /// Lines with no mass (invalid, warming up).
    pub no_mass: u64,
    /// The largest error of a shown reading over its permissible error.
    pub worst_ratio: f64,
}

impl Tally {
    fn add(&mut self, other: &Tally) {
        self.readings += other.readings;
        self.shown += other.shown;
        self.silent_wrong += other.silent_wrong;
        self.flagged_wrong += other.flagged_wrong;
        self.no_mass += other.no_mass;
        self.worst_ratio = self.worst_ratio.max(other.worst_ratio);
    }
}

/// The tallies of runs, per act, and the worst silent wrong readings.
#[derive(Clone, Debug, Default)]
pub struct Tallies {
    /// Per act kind.
    pub by_act: BTreeMap<ActKind, Tally>,
    /// The silent wrong readings with the largest error ratio (at most [`Self::KEEP`]).
    pub worst: Vec<Wrong>,
    /// Silent wrong readings by their error over the `u` shown with them: below 2, 2–3,
    /// 3–5, 5 and more, no `u` stated. Below 3 the stated `u` covered the error and the
    /// stability rule let it through; far above, `u` did not describe the data.
    pub silent_by_z: [u64; 5],
    /// Silent wrong readings by how long the loads on the pan had spanned no more than the
    /// permissible error (`Line::steady_s`): below 0.1 s, 0.1–0.5 s, 0.5–2 s, 2 s and more.
    /// Below 0.1 s the load moved within the last two readout lines: a change the data
    /// had barely begun to show; from 2 s on it had been at rest while the fit was wrong.
    pub silent_by_steady: [u64; 4],
    /// Silent wrong readings by the evidence against them in the data at their line
    /// ([`Evidence::z`]): below 2, 2–3, 3–5, 5 and more. Below 2 no test could have seen
    /// the change in time, however good: it had not yet shown in the data above its noise.
    pub silent_by_evidence: [u64; 4],
    /// Lines shown settled by how finely one readout line's data resolved their
    /// permissible error ([`Line::resolution`]): below 2, 2–3, 3–5, 5 and more, not yet
    /// known. Below 2 a change of the permissible error that began a whole line before
    /// stood out of one line's mean by less than two of its standard errors: what a test
    /// could see of it in time, at best, and what showing no such line would cost.
    pub shown_by_resolution: [u64; 5],
    /// Silent wrong readings in the same buckets.
    pub silent_by_resolution: [u64; 5],
    /// Lines with no mass by why ([`NoMass`], in its order).
    pub no_mass_by_why: [u64; 4],
    /// Runs tallied.
    pub runs: u64,
}

impl Tallies {
    /// Silent wrong readings kept to show.
    pub const KEEP: usize = 8;

    /// Count one judged readout line of `act`; `at` is (run, time in s, state shown), kept
    /// with a silent wrong reading, and `evidence` what the data held against the mass
    /// shown (asked only of a silent wrong reading: see [`Evidence::z`]).
    pub fn judge(
        &mut self,
        act: ActKind,
        line: Line,
        limits: &Limits,
        at: (u64, f64, &'static str),
        evidence: impl FnOnce(f64) -> f64,
    ) {
        let tally = self.by_act.entry(act).or_default();
        tally.readings += 1;
        let shown_g = match line.mass_g {
            Ok(shown_g) => shown_g,
            Err(why) => {
                tally.no_mass += 1;
                self.no_mass_by_why[why as usize] += 1;
                return;
            }
        };
        let mid = 0.5 * (line.truth.low_g + line.truth.high_g);
        let permissible = limits.permissible_g(mid);
        let over_capacity = line.truth.gross_low_g > limits.overload_g();
        let error = line.truth.error_g(shown_g);
        let is_wrong = error > permissible || over_capacity;
        if !line.settled {
            if is_wrong {
                tally.flagged_wrong += 1;
            }
            return;
        }
        tally.shown += 1;
        let resolution = line.resolution(permissible);
        self.shown_by_resolution[resolution_bucket(resolution)] += 1;
        let ratio = if over_capacity {
            f64::INFINITY
        } else {
            error / permissible
        };
        tally.worst_ratio = tally.worst_ratio.max(ratio);
        if is_wrong {
            tally.silent_wrong += 1;
            self.silent_by_z[z_bucket(error, line.u_g)] += 1;
            self.silent_by_steady[steady_bucket(line.steady_s)] += 1;
            let evidence_z = evidence(shown_g);
            self.silent_by_evidence[z_of(evidence_z)] += 1;
            self.silent_by_resolution[resolution_bucket(resolution)] += 1;
            let (run, time_s, state) = at;
            self.worst.push(Wrong {
                run,
                time_s,
                act,
                shown_g,
                truth_g: (line.truth.low_g, line.truth.high_g),
                error_g: if over_capacity { f64::INFINITY } else { error },
                permissible_g: permissible,
                state,
                steady_s: line.steady_s,
                evidence_z,
                resolution,
            });
            self.keep_worst();
        }
    }

    /// Merge the tallies of other runs.
    pub fn merge(&mut self, other: Tallies) {
        for (act, tally) in &other.by_act {
            self.by_act.entry(*act).or_default().add(tally);
        }
        self.worst.extend(other.worst);
        add_counts(&mut self.silent_by_z, &other.silent_by_z);
        add_counts(&mut self.silent_by_steady, &other.silent_by_steady);
        add_counts(&mut self.silent_by_evidence, &other.silent_by_evidence);
        add_counts(&mut self.shown_by_resolution, &other.shown_by_resolution);
        add_counts(&mut self.silent_by_resolution, &other.silent_by_resolution);
        add_counts(&mut self.no_mass_by_why, &other.no_mass_by_why);
        self.keep_worst();
        self.runs += other.runs;
    }

    /// Keep the [`Self::KEEP`] wrong readings with the largest error over permissible
    /// (ties: the earliest run and time), so the list does not depend on the threads.
    fn keep_worst(&mut self) {
        self.worst.sort_by(|a, b| {
            let ra = a.error_g / a.permissible_g;
            let rb = b.error_g / b.permissible_g;
            rb.total_cmp(&ra)
                .then(a.run.cmp(&b.run))
                .then(a.time_s.total_cmp(&b.time_s))
        });
        self.worst.truncate(Self::KEEP);
    }

    /// All acts together.
    pub fn total(&self) -> Tally {
        let mut total = Tally::default();
        for tally in self.by_act.values() {
            total.add(tally);
        }
        total
    }
}

/// Add the counts of `theirs` to `mine`, bucket by bucket.
fn add_counts(mine: &mut [u64], theirs: &[u64]) {
    for (mine, theirs) in mine.iter_mut().zip(theirs) {
        *mine += theirs;
    }
}

/// The bucket of [`Tallies::silent_by_z`] for an error of `error_g` shown with `u_g`.
fn z_bucket(error_g: f64, u_g: Option<f64>) -> usize {
    match u_g {
        Some(u) if u > 0.0 => z_of(error_g / u),
        _ => 4,
    }
}

/// The bucket of a z: below 2, 2–3, 3–5, 5 and more (NaN: the last).
fn z_of(z: f64) -> usize {
    if z < 2.0 {
        0
    } else if z < 3.0 {
        1
    } else if z < 5.0 {
        2
    } else {
        3
    }
}

/// The bucket of [`Tallies::shown_by_resolution`]: a z's ([`z_of`]), or the last when
/// not yet known.
fn resolution_bucket(resolution: Option<f64>) -> usize {
    resolution.map_or(4, z_of)
}

/// How long the load must have stood still before a line counts towards the pan's
/// [`LineScatter`], s: a heavy drop's ringing has died down by then (the reference cell's
/// decays by e⁻⁷ in 1.5 s).
pub const SCATTER_STILL_S: f64 = 1.5;

/// Pairs of still lines before [`LineScatter::sigma_g`] answers: one second of them.
const SCATTER_MIN_PAIRS: u64 = 20;

/// The scatter of one readout line's mean on a pan: how finely the data of a single line
/// resolve the load. From consecutive still lines (no change of the load in either, steady
/// for [`SCATTER_STILL_S`], every sample good), half their differences' mean square is one
/// line mean's variance, whatever the noise is made of (the converter's, the amplifier's
/// through the filter, floor vibration, mains) as far as it reaches a line's mean.
#[derive(Clone, Copy, Debug, Default)]
pub struct LineScatter {
    previous_g: Option<f64>,
    sum_g2: f64,
    pairs: u64,
}

impl LineScatter {
    /// One line's mean of the raw samples in grams, or `None` for a line that is not still
    /// (it ends the pair it would have formed).
    pub fn push(&mut self, mean_g: Option<f64>) {
        if let (Some(now), Some(before)) = (mean_g, self.previous_g) {
            let difference = now - before;
            if difference.is_finite() {
                self.sum_g2 += difference * difference;
                self.pairs += 1;
            }
        }
        self.previous_g = mean_g;
    }

    /// The standard deviation of one line's mean, g, once [`SCATTER_MIN_PAIRS`] pairs of
    /// still lines have been seen.
    pub fn sigma_g(&self) -> Option<f64> {
        (self.pairs >= SCATTER_MIN_PAIRS).then(|| (0.5 * self.sum_g2 / self.pairs as f64).sqrt())
    }
}

/// The true net loads of the last samples, for what a silent wrong reading's data held
/// against it: whether the change it missed had shown in the samples at all by its line.
#[derive(Clone, Debug)]
pub struct Evidence {
    loads_g: Vec<f64>,
    next: usize,
    filled: usize,
    noise_g: f64,
}

impl Evidence {
    /// The last `samples` true loads, against white noise of `noise_g` per sample.
    pub fn new(samples: usize, noise_g: f64) -> Self {
        Self {
            loads_g: vec![0.0; samples.max(1)],
            next: 0,
            filled: 0,
            noise_g,
        }
    }

    /// The true net load of the next sample, g.
    pub fn push(&mut self, load_g: f64) {
        self.loads_g[self.next] = load_g;
        self.next = (self.next + 1) % self.loads_g.len();
        self.filled = (self.filled + 1).min(self.loads_g.len());
    }

    /// The largest z of the true loads' mean against `shown_g`, over every stretch of the
    /// kept samples that ends now and lies wholly on the side of the reading the load is
    /// on now: `|Σ (load − shown)| / (σ √n)` for the last n samples, σ the white noise
    /// alone. What a test that knew the change's moment and had no other noise to allow
    /// for (no vibration, no mains, no ringing, no lag of the sensor) would have held
    /// against the reading: an upper bound on any real test's evidence. (Loads on the other
    /// side, such as the load before a removal, say the pan held something else then, not
    /// that the reading is wrong now.)
    pub fn z(&self, shown_g: f64) -> f64 {
        let len = self.loads_g.len();
        let mut sum = 0.0;
        let mut best: f64 = 0.0;
        for back in 0..self.filled {
            let deviation = self.loads_g[(self.next + len - 1 - back) % len] - shown_g;
            if deviation * sum < 0.0 {
                break;
            }
            sum += deviation;
            best = best.max(sum.abs() / (self.noise_g * ((back + 1) as f64).sqrt()));
        }
        best
    }
}

/// The bucket of [`Tallies::silent_by_steady`] for a load steady for `steady_s`.
fn steady_bucket(steady_s: f64) -> usize {
    if steady_s < 0.1 {
        0
    } else if steady_s < 0.5 {
        1
    } else if steady_s < 2.0 {
        2
    } else {
        3
    }
}

/// Why a line shows no mass: the columns of [`Tallies::no_mass_by_why`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoMass {
    /// No estimate yet (a fresh run).
    NotYet = 0,
    /// The consistency check flagged the run's fit (`InvalidReason::ModelMismatch`).
    ModelMismatch = 1,
    /// The estimator flagged its reading for another reason (ill-conditioned, a bank's fit
    /// on its edge, a latched fault).
    EstimatorFlag = 2,
    /// The scale's own fault: overload, a saturated or lost sample.
    Fault = 3,
}

/// One readout line as judged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line {
    /// The mass shown, g, or why none is.
    pub mass_g: Result<f64, NoMass>,
    /// Shown as settled (stable, empty or final).
    pub settled: bool,
    /// The standard uncertainty shown with the mass, g (`None`: none stated).
    pub u_g: Option<f64>,
    /// What was on the pan.
    pub truth: Truth,
    /// How long the loads on the pan had spanned no more than the permissible error, s (see
    /// [`Steadiness`]).
    pub steady_s: f64,
    /// The scatter of one line's mean on the pan so far ([`LineScatter::sigma_g`]), g.
    pub line_sigma_g: Option<f64>,
}

impl Line {
    /// How many standard errors of one line's mean the permissible error `permissible_g`
    /// is on this pan: how far a change of that size, begun a whole line before, stood out
    /// of the data of the line; `None` before the pan's scatter is known.
    pub fn resolution(&self, permissible_g: f64) -> Option<f64> {
        self.line_sigma_g
            .filter(|&sigma| sigma > 0.0)
            .map(|sigma| permissible_g / sigma)
    }
}

/// How long the load on the pan has stayed put: the clock starts over whenever the loads
/// since it last started span more than the permissible error. A step starts it over at
/// once, a trickle each time it has added one permissible error. (Anchored at one load
/// instead, a load that overshot and came back, as a hand places it, left the anchor at
/// the overshoot, and a later step smaller than the permissible error from there went
/// uncounted: a small addition of 0.14 g on 208 g was said steady for 55.6 s.)
#[derive(Clone, Copy, Debug)]
pub struct Steadiness {
    low_g: f64,
    high_g: f64,
    since_sample: u64,
}

impl Steadiness {
    /// At rest at `load_g` from the first sample.
    pub fn new(load_g: f64) -> Self {
        Self {
            low_g: load_g,
            high_g: load_g,
            since_sample: 0,
        }
    }

    /// The gross load at `sample`.
    pub fn push(&mut self, sample: u64, load_g: f64, limits: &Limits) {
        let low = self.low_g.min(load_g);
        let high = self.high_g.max(load_g);
        if high - low > limits.permissible_g(load_g) {
            self.low_g = load_g;
            self.high_g = load_g;
            self.since_sample = sample;
        } else {
            self.low_g = low;
            self.high_g = high;
        }
    }

    /// Seconds the load has stayed put as of `sample`, at `rate_hz`.
    pub fn steady_s(&self, sample: u64, rate_hz: f64) -> f64 {
        sample.saturating_sub(self.since_sample) as f64 / rate_hz
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> Limits {
        Limits {
            capacity_g: 600.0,
            scale_interval_g: 0.1,
            target_relative: 5e-4,
            target_mass_g: 138.32,
        }
    }

    #[test]
    fn mpe_steps_at_500_and_2000_intervals() {
        let l = limits();
        assert_eq!(l.mpe_class_iii_g(50.0), 0.05);
        assert_eq!(l.mpe_class_iii_g(50.01), 0.1);
        assert_eq!(l.mpe_class_iii_g(200.0), 0.1);
        assert_eq!(l.mpe_class_iii_g(200.1), 0.15000000000000002);
        // The target (0.05 % of 138.32 g = 0.069 g) is tighter than 1 e at 100 g.
        assert!((l.permissible_g(100.0) - 0.06916).abs() < 1e-9);
        // At 600 g, 0.05 % is 0.3 g: the MPE (1.5 e) is tighter.
        assert!((l.permissible_g(600.0) - 0.15).abs() < 1e-9);
    }

    #[test]
    fn a_stable_mass_above_max_plus_9e_is_wrong_even_when_accurate() {
        let mut tallies = Tallies::default();
        let line = Line {
            mass_g: Ok(660.0),
            settled: true,
            u_g: None,
            truth: Truth {
                low_g: 660.0,
                high_g: 660.0,
                gross_low_g: 660.0,
            },
            steady_s: 10.0,
            line_sigma_g: Some(0.1),
        };
        let at = (0, 0.0, "stable");
        tallies.judge(ActKind::Overload, line, &limits(), at, |_| 9.0);
        assert_eq!(tallies.worst[0].error_g, f64::INFINITY);
        assert_eq!(tallies.total().silent_wrong, 1);
        assert_eq!(tallies.silent_by_steady, [0, 0, 0, 1]);
        assert_eq!(tallies.silent_by_evidence, [0, 0, 0, 1]);
        // 1.5 e (0.15 g) over one line's scatter of 0.1 g.
        assert_eq!(tallies.worst[0].resolution, Some(1.5000000000000002));
        assert_eq!(tallies.silent_by_resolution, [1, 0, 0, 0, 0]);
        assert_eq!(tallies.shown_by_resolution, [1, 0, 0, 0, 0]);
        // The same line flagged (estimating) is a flagged wrong reading, not a silent one.
        let mut tallies = Tallies::default();
        tallies.judge(
            ActKind::Overload,
            Line {
                settled: false,
                ..line
            },
            &limits(),
            at,
            |_| unreachable!("asked only of a silent wrong reading"),
        );
        assert_eq!(tallies.total().silent_wrong, 0);
        assert_eq!(tallies.total().flagged_wrong, 1);
    }

    #[test]
    fn lines_without_a_mass_are_counted_by_why() {
        let line = |why| Line {
            mass_g: Err(why),
            settled: false,
            u_g: None,
            truth: Truth {
                low_g: 100.0,
                high_g: 100.0,
                gross_low_g: 100.0,
            },
            steady_s: 1.0,
            line_sigma_g: None,
        };
        let mut tallies = Tallies::default();
        tallies.judge(
            ActKind::Trickle,
            line(NoMass::ModelMismatch),
            &limits(),
            (0, 0.0, "invalid"),
            |_| unreachable!(),
        );
        let mut other = Tallies::default();
        other.judge(
            ActKind::Overload,
            line(NoMass::Fault),
            &limits(),
            (1, 0.0, "invalid"),
            |_| unreachable!(),
        );
        other.judge(
            ActKind::Overload,
            line(NoMass::ModelMismatch),
            &limits(),
            (1, 0.1, "invalid"),
            |_| unreachable!(),
        );
        tallies.merge(other);
        assert_eq!(tallies.no_mass_by_why, [0, 2, 0, 1]);
        assert_eq!(tallies.total().no_mass, 3);
    }

    #[test]
    fn settled_lines_are_counted_by_how_finely_one_line_resolves_their_error() {
        let line = |sigma: Option<f64>| Line {
            mass_g: Ok(10.0),
            settled: true,
            u_g: Some(0.01),
            truth: Truth {
                low_g: 10.0,
                high_g: 10.0,
                gross_low_g: 10.0,
            },
            steady_s: 5.0,
            line_sigma_g: sigma,
        };
        let mut tallies = Tallies::default();
        // 0.05 g permissible at 10 g: over 0.03, 0.02, 0.0125, 0.005 g and unknown.
        for sigma in [Some(0.03), Some(0.02), Some(0.0125), Some(0.005), None] {
            tallies.judge(
                ActKind::Hand,
                line(sigma),
                &limits(),
                (0, 0.0, "stable"),
                |_| unreachable!("not wrong"),
            );
        }
        assert_eq!(tallies.shown_by_resolution, [1, 1, 1, 1, 1]);
        assert_eq!(tallies.silent_by_resolution, [0; 5]);
        // A scatter of zero (a pan without noise) says nothing it could resolve.
        assert_eq!(line(Some(0.0)).resolution(0.05), None);
    }

    #[test]
    fn the_line_scatter_is_one_line_means_standard_deviation() {
        let mut rng = crate::simulated::Gaussian::new(7);
        let mut scatter = LineScatter::default();
        // Still lines about 100 g with a scatter of 0.03 g, pairs broken now and then by
        // a line that is not still (which must not pair across the break: a step of 5 g
        // there would dominate the sum).
        for line in 0..4000 {
            if line % 50 == 0 {
                scatter.push(None);
                continue;
            }
            let level = if line < 2000 { 100.0 } else { 105.0 };
            scatter.push(Some(level + 0.03 * rng.standard()));
            if line == 15 {
                assert_eq!(scatter.sigma_g(), None, "fewer than 20 pairs");
            }
        }
        let sigma = scatter.sigma_g().unwrap();
        assert!((sigma - 0.03).abs() < 0.0015, "{sigma}");
    }

    #[test]
    fn the_load_is_steady_from_its_last_move_beyond_the_permissible_error() {
        let limits = limits();
        let rate_hz = 4000.0;
        let mut steady = Steadiness::new(0.0);
        // At rest on 100 g from sample 400, wobbling by less than the permissible error.
        for sample in 0..4400_u64 {
            let load = if sample < 400 {
                0.0
            } else {
                100.0 + 0.04 * (sample % 2) as f64
            };
            steady.push(sample, load, &limits);
        }
        assert!((steady.steady_s(4400, rate_hz) - 1.0).abs() < 1e-9);
        // Placed by hand onto an empty pan: 0.06 g over, back to 100 g, then 0.06 g more:
        // within the permissible error (0.069 g) of the overshoot, but not of every load
        // since (an anchor left at the overshoot said steady since it).
        let mut placed = Steadiness::new(0.0);
        for (sample, load) in [(400, 100.06), (800, 100.0)] {
            placed.push(sample, load, &limits);
        }
        assert!((placed.steady_s(1200, rate_hz) - 0.2).abs() < 1e-9);
        placed.push(1200, 100.12, &limits);
        assert_eq!(placed.steady_s(1200, rate_hz), 0.0);
        // A trickle of 0.5 g/s: started over each time it has added one permissible error
        // (0.069 g at 100 g, the target's), so once it has, never steady for more than
        // 0.14 s.
        let mut load = 100.0;
        for sample in 4400..12_400_u64 {
            load += 0.5 / rate_hz;
            steady.push(sample, load, &limits);
            if sample >= 4400 + 560 {
                assert!(steady.steady_s(sample + 1, rate_hz) <= 0.14, "{sample}");
            }
        }
    }

    #[test]
    fn the_evidence_is_the_best_stretch_ending_now() {
        // 1 g of white noise; 100 samples at 10 g, then 16 at 10.5 g: against 10 g shown,
        // the last 16 samples give 0.5 × 16 / (1 × 4) = 2, and longer stretches less.
        let mut evidence = Evidence::new(1000, 1.0);
        for sample in 0..116 {
            evidence.push(if sample < 100 { 10.0 } else { 10.5 });
        }
        assert!((evidence.z(10.0) - 2.0).abs() < 1e-12);
        // Shown at 10.25 g, the load is above it now: the stretch stops where it was
        // below, however much that held (0.25 × 16 / 4 = 1).
        assert!((evidence.z(10.25) - 1.0).abs() < 1e-12);
        // Shown at 10.5 g the newest samples are no evidence at all, and the stretch
        // goes on over them into the 100 below it: 50 / √116.
        assert!((evidence.z(10.5) - 50.0 / 116f64.sqrt()).abs() < 1e-12);
        // Only the kept samples count: the last 16 of a ring of 16.
        let mut short = Evidence::new(16, 1.0);
        for sample in 0..116 {
            short.push(if sample < 100 { 10.0 } else { 10.5 });
        }
        assert!((short.z(10.5) - 0.0).abs() < 1e-12);
    }

    #[test]
    fn a_display_may_lag_one_period() {
        let truth = Truth {
            low_g: 100.0,
            high_g: 100.5,
            gross_low_g: 100.0,
        };
        assert_eq!(truth.error_g(100.2), 0.0);
        assert!((truth.error_g(100.7) - 0.2).abs() < 1e-12);
        assert!((truth.error_g(99.9) - 0.1).abs() < 1e-12);
    }
}
