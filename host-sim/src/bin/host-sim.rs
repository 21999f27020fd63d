//! `host-sim`: simulate scenes, run the core's estimator on recorded data, Monte Carlo
//! studies against the Cramér–Rao bound, the charts, the results table and the benchmark.
//! Each subcommand is one function; the work is in the library, never here.

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use estimator_core::sensor::AdcSource;
use host_sim::calibrate;
use host_sim::chart;
use host_sim::estimate::{estimate_csv, estimate_with};
use host_sim::method::{BuildContext, Method};
use host_sim::montecarlo::{self, Precision, Setup, Study};
use host_sim::recording::{self, Layout};
use host_sim::scene::Scene;
use host_sim::study;

#[derive(Parser)]
#[command(
    name = "host-sim",
    version,
    about = "The weighing scene, Monte Carlo studies and charts"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a scene: CSV `t,y,truth` (t in s, y the ADC code, truth the load in g).
    Simulate(SimulateArgs),
    /// Run one of the core's estimators over a recording (a CSV of raw samples, by default a
    /// column `y` under a header); writes `k,estimate,u,state` to stdout (estimate empty
    /// while not valid). Give `--method SPEC`
    /// (e.g. `model:D=8`, `settled`, `step:n=7,D=16,precision=f32`), or the step estimator's
    /// shorthand `--order N [--decimation D --forgetting L --precision P]`.
    Estimate(EstimateArgs),
    /// Calibration as one command: from recorded drops of a known mass (CSVs of raw samples,
    /// by default a column `y` under a header: an empty-pan stretch, then the drop), choose the smallest method that meets the
    /// target at the readout time and write the weighing configuration (TOML). Each scored
    /// candidate is logged on stderr; the choice and its figures on stdout.
    Calibrate(CalibrateArgs),
    /// Monte Carlo of the core on a scene: CSV per SNR, configuration and sample index.
    Montecarlo(MontecarloArgs),
    /// The README's results table: the plain thesis configuration and a sweep of order and
    /// decimation on the reference scene at 50 dB; prints the figures and the best one.
    Table(TableArgs),
    /// Draw the charts (a)–(d) as SVG and PNG.
    Chart(ChartArgs),
    /// Studies over every method. `study speed`: speed against accuracy on the reference
    /// scene at 30–80 dB (time to 0.1%, RMS at 50/100/200 ms against the CRLB), CSV +
    /// markdown + charts, and the firmware default's goal figures.
    Study(StudyArgs),
    /// Monte Carlo benchmark: estimator updates per second on this host.
    Bench(BenchArgs),
    /// The firmware's scale over random sequences of weighings (loads to beyond capacity,
    /// placed by hand, dropped, small additions, trickles, noise kinds, lost samples, tare
    /// and calibration): counts the readings shown settled whose error exceeds the maximum
    /// permissible error. Last line: `silent wrong readings: W of M shown in N runs`; exits
    /// non-zero when W > 0.
    Torture(TortureArgs),
    /// Run exactly what the firmware runs (the scale with the configured method, onset
    /// detection, zero tracking, flags) on a recording or a scene, and print its readout as
    /// CSV `t_s,mass_g,u_g,state,final`, one row per 20 Hz readout line. `estimate` runs
    /// the bare estimator; this runs the instrument.
    Replay(ReplayArgs),
    /// A live view of a weighing board: reads its lines (the serial console, the firmware's
    /// log from probe-rs or QEMU, or `replay`'s CSV) from a file, a serial device or stdin,
    /// plots mass with its ±2u band and logs every reading as CSV. On a terminal it is
    /// interactive (q quits); otherwise it prints the last frame as text.
    Monitor(MonitorArgs),
    /// The recordings a board wrote on its serial console (`record`: RECORD begin, D lines,
    /// RECORD end) as CSVs `t,y` that `calibrate`, `estimate` and `replay` read: one file
    /// per recording, `<out-dir>/<prefix>-<n>.csv`. A recording cut short or with a line
    /// lost on the way is refused with its line.
    Records(RecordsArgs),
}

#[derive(Args)]
struct RecordsArgs {
    /// The console transcript (what a terminal or `cat /dev/ttyACM0` saved); `-` for stdin.
    #[arg(long)]
    console: PathBuf,
    /// Where the CSVs go (created if missing).
    #[arg(long, default_value = ".")]
    out_dir: PathBuf,
    /// The files' name before `-<n>.csv`.
    #[arg(long, default_value = "record")]
    prefix: String,
}

#[derive(Args)]
struct MonitorArgs {
    /// Where the lines come from: a file, a serial device (e.g. /dev/ttyACM0), or - for stdin.
    #[arg(long, default_value = "-")]
    input: PathBuf,
    /// Log every reading to this CSV (t_s,mass_g,u_g,state,final).
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Seconds of readings on the plot.
    #[arg(long, default_value_t = 5.0)]
    window_s: f64,
    /// The sample rate that times the firmware's log lines (`sample=`), Hz.
    #[arg(long, default_value_t = 4000.0)]
    sample_rate_hz: f64,
    /// Print the last frame as text even on a terminal.
    #[arg(long)]
    text: bool,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct ReplayArgs {
    /// A recording: a CSV of ADC codes (by default a column `y` under a header) at the
    /// configuration's sample rate. Converted with the configuration's gain and zero.
    #[arg(long, conflicts_with = "scene", required_unless_present = "scene")]
    input: Option<PathBuf>,
    #[command(flatten)]
    recording: RecordingArgs,
    /// A scene file or the name of a shipped scene, simulated on its own chain and converted
    /// with that chain's gain and zero (a board calibrated on that cell); or `qemu-demo`,
    /// `qemu-checked-demo`: the QEMU board's scenes with its factory calibration, exactly
    /// what `cargo xtask demo` plays.
    #[arg(long)]
    scene: Option<String>,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The weighing configuration (default: the firmware's shipped one, built in).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Convert with this gain instead (counts per gram).
    #[arg(long)]
    counts_per_gram: Option<f64>,
    /// Convert with this zero instead (counts).
    #[arg(long)]
    zero_counts: Option<f64>,
}

/// Where a recording's samples are: the options of every command that reads one.
#[derive(Args)]
struct RecordingArgs {
    /// The column of raw samples: its name in the header (default `y`), or with --no-header
    /// its 0-based index (default: the only column). A recording may separate its fields
    /// with `,`, `;` or tabs (found from its first line), start with a UTF-8 byte order mark
    /// and quote its header.
    #[arg(long, value_name = "NAME|INDEX")]
    column: Option<String>,
    /// The recording has no header: every line holds samples (e.g. one bare number a line).
    #[arg(long)]
    no_header: bool,
}

impl RecordingArgs {
    fn layout(&self) -> Layout {
        Layout {
            column: self.column.clone(),
            no_header: self.no_header,
        }
    }

    fn given(&self) -> bool {
        self.column.is_some() || self.no_header
    }
}

#[derive(Args)]
struct TortureArgs {
    #[arg(long, default_value_t = 100)]
    runs: u64,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Run only this run of the seed (to reproduce one listed in the report).
    #[arg(long)]
    only_run: Option<u64>,
    /// With --only-run: write every readout line of the run (truth, shown, state, act) and
    /// each command's outcome as CSV to this file.
    #[arg(long, requires = "only_run")]
    trace: Option<PathBuf>,
    /// The weighing configuration the scale is built from (default: the firmware's shipped
    /// one, built into this binary).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Max, g (default: the configuration's).
    #[arg(long)]
    capacity_g: Option<f64>,
    /// The scale interval e, g (default: the configuration's).
    #[arg(long)]
    e_g: Option<f64>,
    /// Worker threads (default: the machine's).
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct SimulateArgs {
    /// A scene file, or the name of a shipped scene (built into this binary, e.g.
    /// reference-step, calibration-drop, placed-by-hand).
    scene: String,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[arg(long)]
    out: PathBuf,
    /// White noise at this SNR instead of the scene's (dB, thesis eq. 4.39, relative to
    /// the scene's SNR step).
    #[arg(long)]
    snr_db: Option<f64>,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct EstimateArgs {
    /// The recording: a CSV of raw samples, one a row.
    #[arg(long)]
    input: PathBuf,
    #[command(flatten)]
    recording: RecordingArgs,
    /// A weighing configuration written by `calibrate`: runs the configured method's bare
    /// estimator as the firmware builds it, with its gain and zero (--zero overrides the
    /// zero), its fit checked against the configuration's noise. It assumes the load landed
    /// at the first row: `replay` runs the whole scale (onset detection, load changes).
    #[arg(long, conflicts_with_all = ["method", "order", "forgetting", "decimation", "precision", "gain"])]
    config: Option<PathBuf>,
    /// The estimator: step, covariance, model, settled, moving, ramp, iv or bc with its
    /// keys (see host-sim/README.md).
    #[arg(long, conflicts_with_all = ["order", "forgetting", "decimation", "precision"])]
    method: Option<Method>,
    /// Shorthand for `--method step:n=N,...`: model order n.
    #[arg(long, required_unless_present_any = ["method", "config"])]
    order: Option<usize>,
    /// Static gain: raw units of `y` per unit of the estimate (e.g. counts per gram).
    #[arg(long, required_unless_present = "config")]
    gain: Option<f64>,
    #[arg(long)]
    forgetting: Option<f64>,
    #[arg(long)]
    decimation: Option<u16>,
    #[arg(long)]
    precision: Option<Precision>,
    /// Subtracted from every sample before the estimator (the tare, in raw units; default
    /// 0, or the config's zero).
    #[arg(long)]
    zero: Option<f64>,
    /// The scene whose sensor chain the `model` method takes its dynamics from.
    #[arg(long, default_value = "reference-step")]
    scene: String,
    /// Noise variance of one raw sample measured at tare, raw units² (for `bc`, and the
    /// reference of `--check-residuals`), metered at the method's D.
    #[arg(long)]
    tare_variance: Option<f64>,
    /// The differences of block means the tare variance was metered over (its own
    /// uncertainty, for `--check-residuals`; default: known exactly).
    #[arg(long, default_value_t = 0, requires = "check_residuals")]
    tare_differences: u32,
    /// Flag a fit whose residuals exceed what the tare's noise explains
    /// (`invalid_model_mismatch`; estimator-core's consistency check). Needs
    /// `--tare-variance`.
    #[arg(long, requires = "tare_variance", conflicts_with = "config")]
    check_residuals: bool,
    /// With --config: do not check the fit against the configuration's measured noise
    /// (checked by default, so a record the method does not fit, e.g. an empty pan before
    /// the drop, is flagged `invalid_model_mismatch` instead of read far off).
    #[arg(long, requires = "config")]
    no_check_residuals: bool,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct CalibrateArgs {
    /// A recorded drop (repeat for each; 3 is typical).
    #[arg(long = "drop", required = true)]
    drops: Vec<PathBuf>,
    /// How every drop (and second drop) is laid out.
    #[command(flatten)]
    recording: RecordingArgs,
    /// The known mass dropped, g.
    #[arg(long)]
    mass_g: f64,
    /// Readout time after the mass lands, ms.
    #[arg(long, default_value_t = 100.0)]
    readout_ms: f64,
    /// Accuracy target at the readout, % of the mass (95th percentile of |error|).
    #[arg(long, default_value_t = 0.1)]
    target_pct: f64,
    /// Static gain to use; default: derived from the drops (the identified model's fitted
    /// step over the known mass).
    #[arg(long)]
    counts_per_gram: Option<f64>,
    /// Where the configuration goes.
    #[arg(long)]
    out: PathBuf,
    /// Sample rate of the recordings, Hz.
    #[arg(long, default_value_t = 4000.0)]
    sample_rate_hz: f64,
    /// Cut-off of the known 3rd-order Butterworth anti-alias filter, Hz.
    #[arg(long, default_value_t = 100.0)]
    filter_hz: f64,
    /// Converter resolution (codes at 0 or 2^bits − 1 are saturated).
    #[arg(long, default_value_t = 16)]
    adc_bits: u32,
    /// Synthetic drops per candidate (at least 59).
    #[arg(long, default_value_t = 400)]
    runs: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Arithmetic the candidates are scored in (the firmware runs f32).
    #[arg(long, default_value = "f32")]
    precision: Precision,
    /// Largest model order n tried.
    #[arg(long, default_value_t = 8)]
    max_order: usize,
    /// Score every candidate, not only up to the first that meets the target.
    #[arg(long)]
    all: bool,
    /// Also score least squares with forgetting (λ < 1). Its readings state no uncertainty,
    /// so a board running it never shows a reading final.
    #[arg(long)]
    forgetting: bool,
    /// Also print the configuration as a Rust constant (for a firmware build script).
    #[arg(long)]
    rust: bool,
    /// Lightest load the target must hold at, g (default: 0.3x the mass). With
    /// --max-load-g, both equal to --mass-g: score the calibration mass only.
    #[arg(long)]
    min_load_g: Option<f64>,
    /// Heaviest load the target must hold at, g (default: 3x the mass, clipped to the
    /// heaviest load whose landing the converter takes).
    #[arg(long)]
    max_load_g: Option<f64>,
    /// Loads spaced geometrically over the range, ends included (1-8).
    #[arg(long, default_value_t = estimator_core::tuning::DEFAULT_LOADS)]
    loads: usize,
    /// The platform's moving mass (pan and the cell's free end), g, if known; default:
    /// unknown, each load scored at both ends of what physics allows.
    #[arg(long, conflicts_with = "second_drop")]
    platform_mass_g: Option<f64>,
    /// A recorded drop of a second known mass (repeat for each): the platform mass is
    /// identified from the two resonances (with --second-mass-g).
    #[arg(long, requires = "second_mass_g")]
    second_drop: Vec<PathBuf>,
    /// The second known mass, g.
    #[arg(long, requires = "second_drop")]
    second_mass_g: Option<f64>,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct MontecarloArgs {
    scene: String,
    #[arg(long, default_value_t = 1000)]
    runs: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// SNRs in dB (comma separated); default: the scene's.
    #[arg(long, value_delimiter = ',')]
    snr_db: Vec<f64>,
    /// Step estimator configurations, e.g. `--config n=7,D=1 --config n=5,D=16`
    /// (default, when neither --config nor --method is given: n=7,D=1).
    #[arg(long = "config")]
    configs: Vec<Setup>,
    /// Any estimator by its spec, e.g. `--method model --method settled`; after the
    /// `--config` ones. The CSV's `config` column holds each one's label.
    #[arg(long = "method")]
    methods: Vec<Method>,
    /// Samples after the onset to study (default: up to the next event or the end).
    #[arg(long)]
    samples: Option<usize>,
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the headline figures (RMS at the readout, time to 0.1%) to stdout.
    #[arg(long)]
    summary: bool,
    #[arg(long, default_value_t = 0.1)]
    readout_s: f64,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct TableArgs {
    #[arg(long, default_value_t = 1000)]
    runs: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[arg(long, default_value_t = 50.0)]
    snr_db: f64,
    #[arg(long, default_value_t = 0.1)]
    readout_s: f64,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct ChartArgs {
    /// Draw all four charts (the only mode so far).
    #[arg(long)]
    all: bool,
    #[arg(long, default_value = "host-sim/charts")]
    out: PathBuf,
    #[arg(long, default_value_t = 1000)]
    runs: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Configurations for (a)–(c).
    #[arg(long = "config", default_values = ["n=7,D=1", "n=7,D=12"])]
    configs: Vec<Setup>,
    #[arg(long, default_value_t = 0.1)]
    readout_s: f64,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct StudyArgs {
    /// `speed` (speed against accuracy), `stability` (the stability map), `coverage` (the
    /// stated uncertainty against the errors) or `ramp`
    /// (conveyor weighing, the `conveyor-ramp` scene: its SNRs default to 30,40,50 dB;
    /// `--method ramp:n=..,D=..` replaces its setups).
    which: StudyKind,
    /// Runs per SNR (speed, default 1000) or per Monte Carlo cell (stability, default 100).
    #[arg(long)]
    runs: Option<usize>,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// SNRs in dB (comma separated); default: speed 30–80, stability 10–80 (step 10).
    #[arg(long, value_delimiter = ',')]
    snr_db: Vec<f64>,
    /// Stability: the orders of slice A (default 1–40, 15 of them).
    #[arg(long, value_delimiter = ',')]
    orders: Vec<usize>,
    /// Stability: samples of each long run (slice D; 0 leaves the slice out).
    #[arg(long, default_value_t = host_sim::stability::LONG_SAMPLES)]
    long_samples: usize,
    /// More methods, after the default list (e.g. a variant under development).
    #[arg(long = "method")]
    methods: Vec<Method>,
    /// Coverage: the scenes (default: reference-step, and rig-noise and vibration for noise
    /// coloured as on the thesis's rig, floor vibration near the resonance and mains). The
    /// SNR sets the white noise; a scene's coloured components stay as the scene has them.
    #[arg(long = "scene")]
    scenes: Vec<String>,
    /// Coverage: a step method's `u` from the residuals alone, the empty pan's noise colour
    /// not metered (as a scale runs it before 3,000 block means of its empty pan).
    #[arg(long)]
    unmetered: bool,
    /// Coverage: also the RMS error and RMS `u` per cell and the runs beyond ±4u and ±5u
    /// (`coverage-diagnostics.md`, and printed).
    #[arg(long)]
    diagnose: bool,
    /// Coverage: only the firmware's scale tables, with the scale built from this weighing
    /// configuration instead of the shipped one (e.g. the shipped one with a model bank as
    /// its method: `cargo xtask bench bank-u` writes it under `target/xtask/`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Where the CSV, the markdown table and the charts go.
    #[arg(long, default_value = "host-sim/charts")]
    out: PathBuf,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct BenchArgs {
    #[arg(long, default_value_t = 10_000)]
    runs: usize,
    #[arg(long, default_value_t = 6000)]
    samples: usize,
    #[arg(long, default_value_t = 7)]
    order: usize,
    #[arg(long, default_value_t = 1)]
    decimation: u16,
    #[arg(long, default_value = "f64")]
    precision: Precision,
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum StudyKind {
    /// Speed against accuracy.
    Speed,
    /// Conveyor weighing: slope error at the end of the `conveyor-ramp` scene's ramp.
    Ramp,
    /// The stability map of every estimator.
    Stability,
    /// Whether the stated uncertainty holds: the share of runs within ±2u, per SNR and
    /// readout time, for the firmware's method, the firmware's bank on the identified model
    /// and that bank calibrated for its `u` (K = 65, five points, whitened) (or each
    /// `--method`).
    Coverage,
}

fn create(path: &PathBuf) -> Result<BufWriter<File>> {
    if let Some(parent) = path.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
    }
    Ok(BufWriter::new(File::create(path).with_context(|| {
        format!("cannot create {}", path.display())
    })?))
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Simulate(args) => simulate(args),
        Command::Estimate(args) => estimate(args),
        Command::Calibrate(args) => calibrate_command(args),
        Command::Montecarlo(args) => montecarlo(args),
        Command::Table(args) => table(args.runs, args.seed, args.snr_db, args.readout_s),
        Command::Chart(args) => chart_command(args),
        Command::Study(args) => study_command(args),
        Command::Bench(args) => bench(args),
        Command::Torture(args) => torture(args),
        Command::Replay(args) => replay(args),
        Command::Monitor(args) => monitor(args),
        Command::Records(args) => records(args),
    }
}

/// `records`: a console transcript's recordings as CSV files.
fn records(args: RecordsArgs) -> Result<()> {
    let text = if args.console.as_os_str() == "-" {
        let mut text = String::new();
        std::io::Read::read_to_string(&mut std::io::stdin(), &mut text)?;
        text
    } else {
        std::fs::read_to_string(&args.console)
            .with_context(|| format!("{}: cannot read it", args.console.display()))?
    };
    let recordings = host_sim::recording::console::unpack(text.lines())
        .with_context(|| format!("{}", args.console.display()))?;
    if recordings.is_empty() {
        anyhow::bail!(
            "{}: no recording (RECORD begin … RECORD end) in it; type `record` on the board's console, then put the load on",
            args.console.display()
        );
    }
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("{}: cannot create it", args.out_dir.display()))?;
    for (index, recording) in recordings.iter().enumerate() {
        let path = args
            .out_dir
            .join(format!("{}-{}.csv", args.prefix, index + 1));
        std::fs::write(&path, recording.to_csv())
            .with_context(|| format!("{}: cannot write it", path.display()))?;
        println!(
            "{}: {} samples at {} Hz, the load change at sample {}, {} lost, {} saturated",
            path.display(),
            recording.samples.len(),
            recording.rate_hz,
            recording.before,
            recording.lost,
            recording.saturated
        );
    }
    Ok(())
}

/// `simulate`: a scene's ADC codes and truth as CSV.
fn simulate(args: SimulateArgs) -> Result<()> {
    let out = args.out;
    let mut scene = Scene::load(&args.scene)?;
    if let Some(snr_db) = args.snr_db {
        scene = scene.with_snr_db(snr_db);
    }
    let mut adc = scene.adc(args.seed);
    let mut file = create(&out)?;
    writeln!(file, "t,y,truth")?;
    let rate = scene.chain.sample_rate_hz;
    for k in 0..scene.samples() {
        let code = adc.read().map_err(|e| anyhow::anyhow!("ADC: {e:?}"))?;
        writeln!(file, "{:.6},{code},{}", k as f64 / rate, adc.load_g())?;
    }
    file.flush()?;
    eprintln!(
        "{}: {} samples at {} Hz; gain {:.6} counts/g, zero {:.3} counts (use: estimate --gain {:.6} --zero {:.3})",
        out.display(),
        scene.samples(),
        rate,
        scene.chain.counts_per_gram(),
        scene.chain.zero_code(),
        scene.chain.counts_per_gram(),
        scene.chain.zero_code()
    );
    Ok(())
}

/// `calibrate`: identify the sensor from the drops, choose the method, write the
/// configuration.
fn calibrate_command(args: CalibrateArgs) -> Result<()> {
    let mut options = calibration_options(&args);
    let names = display_names(&args.drops);
    if let Some(second_mass_g) = args.second_mass_g {
        let platform_mass_g = identify_platform_mass(&args, &names, second_mass_g, &options)?;
        options.platform_mass_g = Some(platform_mass_g);
    }
    let mass_g = args.mass_g;
    eprintln!(
        "calibrate: {} drops of {mass_g} g, target {}% at {} ms, {} synthetic drops per candidate, {:?}",
        args.drops.len(),
        args.target_pct,
        args.readout_ms,
        args.runs,
        args.precision
    );
    let outcome = calibrate::calibrate_files(&options, |score| {
        eprintln!(
            "{}",
            calibrate::score_line(score, mass_g, options.target_relative)
        );
    })?;
    let command: Vec<String> = std::env::args().collect();
    let text = calibrate::to_toml(&outcome, &names, &command.join(" "));
    calibrate::write_file(&args.out, &text)?;
    print_calibration(&outcome, &options, &args.out);
    if args.rust {
        println!("{}", calibrate::rust_const(&outcome.calibrated.config));
    }
    Ok(())
}

/// The calibration's options from the command line (the platform mass as given, if any).
fn calibration_options(args: &CalibrateArgs) -> calibrate::Options {
    calibrate::Options {
        min_load_g: args.min_load_g,
        max_load_g: args.max_load_g,
        loads: args.loads,
        platform_mass_g: args.platform_mass_g,
        readout_s: args.readout_ms * 1e-3,
        target_relative: args.target_pct * 1e-2,
        counts_per_gram: args.counts_per_gram,
        sample_rate_hz: args.sample_rate_hz,
        filter_cutoff_hz: args.filter_hz,
        adc_bits: args.adc_bits,
        runs: args.runs,
        seed: args.seed,
        precision: args.precision,
        evaluate_all: args.all,
        forgetting: args.forgetting,
        max_order: args.max_order,
        layout: args.recording.layout(),
        ..calibrate::Options::new(args.drops.clone(), args.mass_g)
    }
}

/// The paths as they name the drops in messages and in the configuration.
fn display_names(paths: &[PathBuf]) -> Vec<String> {
    paths.iter().map(|p| p.display().to_string()).collect()
}

/// The platform mass from the two resonances of the drops of two known masses; prints the
/// fit.
fn identify_platform_mass(
    args: &CalibrateArgs,
    names: &[String],
    second_mass_g: f64,
    options: &calibrate::Options,
) -> Result<f64> {
    let read = |paths: &[PathBuf]| {
        paths
            .iter()
            .map(|p| calibrate::read_drop(p, &options.layout))
            .collect::<Result<Vec<_>>>()
    };
    let fit = calibrate::platform_mass_from_drops(
        &read(&args.drops)?,
        names,
        &read(&args.second_drop)?,
        &display_names(&args.second_drop),
        second_mass_g,
        options,
    )?;
    println!(
        "platform mass {:.2} g: {} g rings at {:.4} Hz (zeta {:.5}), {} g at {:.4} Hz (zeta {:.5}); the damping follows the law within {:+.2}%",
        fit.platform_mass_g,
        fit.first.0,
        fit.first.1,
        fit.first.2,
        fit.second.0,
        fit.second.1,
        fit.second.2,
        fit.damping_law_misfit() * 100.0
    );
    Ok(fit.platform_mass_g)
}

/// `montecarlo`: the core on many seeded runs of a scene, per SNR and method.
fn montecarlo(args: MontecarloArgs) -> Result<()> {
    let mut setups: Vec<Method> = args.configs.into_iter().map(Method::from).collect();
    setups.extend(args.methods);
    if setups.is_empty() {
        setups.push(Method::from(Setup::new(7, 1)));
    }
    let study = Study {
        samples: args.samples.unwrap_or(usize::MAX),
        scene: Scene::load(&args.scene)?,
        setups,
        runs: args.runs,
        seed: args.seed,
        final_target_g: None,
    };
    let results = montecarlo::run_studies(&study, &args.snr_db)?;
    if let Some(out) = args.out {
        let mut file = create(&out)?;
        montecarlo::write_csv(&results, &mut file)?;
        file.flush()?;
    }
    if args.summary {
        montecarlo::summary(&results, args.readout_s, &mut std::io::stdout())?;
    }
    Ok(())
}

/// `chart --all`: the charts (a)–(d).
fn chart_command(args: ChartArgs) -> Result<()> {
    if !args.all {
        anyhow::bail!("only `chart --all` is implemented: it draws (a)–(d)");
    }
    charts(
        &args.out,
        args.runs,
        args.seed,
        args.configs,
        args.readout_s,
    )
}

/// `bench`: estimator updates per second on this host.
fn bench(args: BenchArgs) -> Result<()> {
    let (runs, samples, precision) = (args.runs, args.samples, args.precision);
    let scene = Scene::load("reference-step")?;
    let setup = Setup {
        order: args.order,
        decimation: args.decimation,
        forgetting: 1.0,
        precision,
    };
    let figures = montecarlo::bench(&scene, &setup, runs, samples, args.seed)?;
    println!(
        "host-sim bench: {runs} runs x {samples} samples, {setup}, {precision:?}, reference-step at {} dB, {} threads",
        scene.snr_db.unwrap_or(f64::INFINITY),
        figures.threads
    );
    // The estimator alone, on 1 and on 2 threads (or the machine's, if it has more), each
    // timed by the wall clock in its own pass over the same records.
    let counts: Vec<usize> = if figures.threads > 2 {
        vec![1, 2, figures.threads]
    } else {
        vec![1, 2]
    };
    let measured = montecarlo::throughput(&scene, &setup, runs, samples, args.seed, &counts)?;
    let single = measured[0].1;
    for (threads, rate) in &measured {
        println!(
            "  estimator: {rate:.3e} updates/s on {threads} thread{} ({:.1} ns/update; {:.2}x one thread, measured)",
            if *threads == 1 { "" } else { "s" },
            1e9 / rate,
            rate / single
        );
    }
    println!(
        "  whole Monte Carlo (simulation + estimator): {:.2} s wall, {:.3e} samples/s (checksum {:.3})",
        figures.wall_s,
        figures.updates as f64 / figures.wall_s,
        figures.checksum
    );
    Ok(())
}

/// `estimate`: a configuration written by `calibrate`, or a method given on the command line.
fn estimate(args: EstimateArgs) -> Result<()> {
    let recording = recording::read(&args.input, &args.recording.layout())?;
    match args.config.clone() {
        Some(config) => {
            estimate_configured(&recording, config, args.zero, !args.no_check_residuals)
        }
        None => estimate_method(&recording, args),
    }
}

/// `estimate --config`: exactly the configured method, as the firmware builds it.
fn estimate_configured(
    recording: &recording::Recording,
    config: PathBuf,
    zero: Option<f64>,
    check_residuals: bool,
) -> Result<()> {
    let (config, precision) = calibrate::load_config(&config)?;
    let zero = zero.unwrap_or(config.zero_counts);
    // The config's measured noise checks the fit unless asked not to (or there is none).
    let noise = Some(config.noise_variance_counts2)
        .filter(|variance| check_residuals && variance.is_finite() && *variance > 0.0);
    if check_residuals && noise.is_none() {
        eprintln!("note: the configuration has no noise variance; the fit is not checked");
    }
    let estimator = calibrate::checked_configured_estimator(&config, precision, zero, noise)?;
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    estimate_with(estimator, recording, zero, &mut out)?;
    out.flush()?;
    Ok(())
}

/// `estimate --method SPEC` or `--order N`: a method and its context from the command line.
fn estimate_method(recording: &recording::Recording, args: EstimateArgs) -> Result<()> {
    let EstimateArgs {
        method,
        order,
        gain,
        forgetting,
        decimation,
        precision,
        zero,
        scene,
        tare_variance,
        tare_differences,
        check_residuals,
        ..
    } = args;
    let method = match (method, order) {
        (Some(method), _) => method,
        (None, Some(order)) => Method::Step(Setup {
            order,
            decimation: decimation.unwrap_or(1),
            forgetting: forgetting.unwrap_or(1.0),
            precision: precision.unwrap_or(Precision::F64),
        }),
        (None, None) => anyhow::bail!("give --method SPEC or --order N"),
    };
    let gain = gain.context("give --gain (or --config)")?;
    let zero = zero.unwrap_or(0.0);
    let context = BuildContext {
        tare_noise_variance: tare_variance,
        tare_differences,
        noise_check: check_residuals,
        ..BuildContext::new(Scene::load(&scene)?.chain, gain)
    };
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    estimate_csv(recording, &method, &context, zero, &mut out)?;
    out.flush()?;
    Ok(())
}

/// `study`: the speed, stability or ramp study.
fn study_command(args: StudyArgs) -> Result<()> {
    match args.which {
        StudyKind::Speed => study_speed(args),
        StudyKind::Stability => study_stability(args),
        StudyKind::Ramp => study_ramp(args),
        StudyKind::Coverage => study_coverage(args),
    }
}

/// `study coverage`: the stated uncertainty against the errors, on the reference drop.
fn study_coverage(args: StudyArgs) -> Result<()> {
    let snr_db = if args.snr_db.is_empty() {
        host_sim::coverage::SNRS_DB.to_vec()
    } else {
        args.snr_db
    };
    let runs = args.runs.unwrap_or(1000);
    let scenes = if args.scenes.is_empty() {
        host_sim::coverage::SCENES
            .iter()
            .map(|s| s.to_string())
            .collect()
    } else {
        args.scenes
    };
    if let Some(config) = &args.config {
        let (weighing, _) = host_sim::calibrate::load_config(config)?;
        let path = args.out.join("coverage.md");
        let mut file = create(&path)?;
        let label = format!("`{}`", config.display());
        scale_coverage(
            (&weighing, &label),
            &scenes,
            runs,
            args.seed,
            &snr_db,
            &mut file,
            None,
        )?;
        file.flush()?;
        println!("wrote {}", path.display());
        return Ok(());
    }
    let defaults = args.methods.is_empty();
    let methods = if args.methods.is_empty() {
        let (firmware, config) = study::firmware_default()?;
        vec![
            firmware,
            study::identified_bank(&config, Precision::F32),
            study::calibrated_bank(&config, Precision::F32),
        ]
    } else {
        args.methods
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let path = args.out.join("coverage.md");
    let mut file = create(&path)?;
    let mut diagnostics = if args.diagnose {
        Some(create(&args.out.join("coverage-diagnostics.md"))?)
    } else {
        None
    };
    let stdout = std::io::stdout();
    let mut charts = Vec::new();
    for scene in &scenes {
        // A scene given as a file is named by its stem in the charts' file names.
        let stem = std::path::Path::new(scene)
            .file_stem()
            .and_then(|stem| stem.to_str())
            .unwrap_or(scene);
        for (m, method) in methods.iter().enumerate() {
            let colour = if args.unmetered {
                host_sim::coverage::Colour::Unknown
            } else {
                host_sim::coverage::Colour::Metered
            };
            let rows = host_sim::coverage::study_with(
                scene,
                method,
                runs as u64,
                args.seed,
                &snr_db,
                colour,
            )?;
            let (name, label) = match (defaults, m) {
                (true, 0) => (
                    format!("coverage-{stem}-firmware"),
                    format!("firmware `{method}`"),
                ),
                (true, 1) => (
                    format!("coverage-{stem}-bank"),
                    "identified-model bank (f32)".to_string(),
                ),
                (true, _) => (
                    format!("coverage-{stem}-calibrated-bank"),
                    "calibrated bank: K = 65, five points, whitened (f32)".to_string(),
                ),
                (false, _) => (format!("coverage-{stem}-{m}"), format!("`{method}`")),
            };
            let title = format!("{label} on {stem}, {runs} runs per SNR");
            host_sim::coverage::write_chart(&rows, &title, &args.out.join(&name))?;
            charts.push(name);
            let colour = match method {
                Method::Step(_) if args.unmetered => {
                    "; its `u` from the residuals alone, the colour not metered".to_string()
                }
                Method::Step(_) => format!(
                    "; its `u` on the empty pan's noise colour, metered over {:.0} s",
                    host_sim::coverage::METERING_S
                ),
                Method::Model(spec) if spec.whitening > 0 && !args.unmetered => format!(
                    "; its block means whitened by the empty pan's noise colour, metered over {:.0} s",
                    host_sim::coverage::METERING_S
                ),
                _ => String::new(),
            };
            let header = format!(
                "`{method}` on `{scene}` (onset and tare known, the noise running {:.0} s before the landing{colour}), {runs} runs per SNR, seed {}:",
                host_sim::coverage::PRE_ROLL_S,
                args.seed
            );
            host_sim::coverage::write_markdown(&rows, &header, &mut stdout.lock())?;
            host_sim::coverage::write_markdown(&rows, &header, &mut file)?;
            println!();
            writeln!(file)?;
            if let Some(diagnostics) = diagnostics.as_mut() {
                diagnose(&rows, &header, diagnostics)?;
            }
        }
    }
    file.flush()?;
    println!(
        "wrote {} and the charts {}.{{svg,png}}",
        path.display(),
        charts.join(", ")
    );
    if defaults {
        let (shipped, _) = host_sim::replay::shipped_config()?;
        scale_coverage(
            (&shipped, "`firmware/weighing.toml`"),
            &scenes,
            runs,
            args.seed,
            &snr_db,
            &mut file,
            diagnostics.as_mut(),
        )?;
        file.flush()?;
        time_to_final(&methods, runs, args.seed, &snr_db, &args.out)?;
    }
    Ok(())
}

/// The firmware's own scale on each scene (`coverage::scale`), built from `weighing` (named
/// `name` in the tables' headers): after its empty pan's colour is metered, and fresh (its
/// `u` from the residuals alone); appended to `coverage.md`.
fn scale_coverage(
    (weighing, name): (&estimator_core::weighing::WeighingConfig, &str),
    scenes: &[String],
    runs: usize,
    seed: u64,
    snr_db: &[f64],
    file: &mut impl Write,
    mut diagnostics: Option<&mut BufWriter<File>>,
) -> Result<()> {
    use host_sim::coverage::scale::{self, Pan};
    for scene in scenes {
        for pan in [Pan::Metered, Pan::Fresh] {
            let rows = scale::study(weighing, scene, runs as u64, seed, snr_db, pan)?;
            let how = match pan {
                Pan::Metered => format!(
                    "after {:.0} s on the empty pan (its colour metered by the scale itself)",
                    scale::METERED_EMPTY_S
                ),
                Pan::Fresh => "just built (its `u` from the residuals alone)".to_string(),
            };
            let header = format!(
                "The firmware's scale ({name}, `Scale::configured`: its own onset detection) on `{scene}`, {how}, the noise running {:.0} s before the landing; its readings at the times after the landing once it saw the landing, {runs} runs per SNR, seed {seed}:",
                host_sim::coverage::PRE_ROLL_S
            );
            scale::write_markdown(&rows, &header, &mut std::io::stdout().lock())?;
            scale::write_markdown(&rows, &header, file)?;
            println!();
            writeln!(file)?;
            if let Some(diagnostics) = diagnostics.as_deref_mut() {
                let cells: Vec<_> = rows.iter().map(|row| row.row.clone()).collect();
                diagnose(&cells, &header, diagnostics)?;
            }
        }
    }
    Ok(())
}

/// `study coverage --diagnose`: the diagnostic table of one coverage table, printed and
/// written to `coverage-diagnostics.md`.
fn diagnose(
    rows: &[host_sim::coverage::SnrRow],
    header: &str,
    file: &mut BufWriter<File>,
) -> Result<()> {
    for out in [&mut std::io::stdout().lock() as &mut dyn Write, file] {
        writeln!(out, "Diagnostics of: {header}")?;
        host_sim::coverage::write_diagnostics(rows, "g", out)?;
        writeln!(out)?;
    }
    Ok(())
}

/// The time to a final reading on the reference drop, against the fixed 100 ms readout,
/// of the firmware default (its `u` on the metered colour, and before it is metered) and
/// the identified-model bank and that bank calibrated for its `u`: `time-to-final.md` (a
/// table for each) and a chart for each (`time-to-final`, `time-to-final-unmetered`,
/// `time-to-final-bank`, `time-to-final-calibrated-bank`).
fn time_to_final(
    methods: &[Method],
    runs: usize,
    seed: u64,
    snr_db: &[f64],
    out: &std::path::Path,
) -> Result<()> {
    use host_sim::coverage::final_time;
    let (_, config) = study::firmware_default()?;
    let target_g = config.final_target_g;
    // The permissible error at the reference drop's 138.32 g (class III at e = 0.1 g: 1 e;
    // the configured 0.05 % where tighter), the limit a final reading must keep.
    let mass_g = 138.32;
    let limit_g = (config.target_relative * mass_g).min(config.scale_interval_g);
    let path = out.join("time-to-final.md");
    let mut file = create(&path)?;
    let mut charts = Vec::new();
    // The firmware default with its `u` on the metered colour and before it is metered
    // (the scale's first 18 s of empty pan), then the banks.
    use host_sim::coverage::Colour;
    let mut runs_of = vec![
        (
            methods[0],
            Colour::Metered,
            "time-to-final",
            "firmware default",
        ),
        (
            methods[0],
            Colour::Unknown,
            "time-to-final-unmetered",
            "firmware default, colour not yet metered",
        ),
    ];
    if let Some(&bank) = methods.get(1) {
        runs_of.push((
            bank,
            Colour::Metered,
            "time-to-final-bank",
            "identified-model bank",
        ));
    }
    if let Some(&calibrated) = methods.get(2) {
        runs_of.push((
            calibrated,
            Colour::Metered,
            "time-to-final-calibrated-bank",
            "calibrated bank (K = 65, five points, whitened)",
        ));
    }
    for (m, (method, colour, name, label)) in runs_of.into_iter().enumerate() {
        let rows = final_time::study(
            "reference-step",
            &method,
            runs as u64,
            seed,
            snr_db,
            target_g,
            colour,
        )?;
        let how = match (method, colour) {
            (Method::Step(_), Colour::Metered) => format!(
                " (the noise running {:.0} s before the landing, its `u` on the empty pan's noise colour metered over {:.0} s)",
                host_sim::coverage::PRE_ROLL_S,
                host_sim::coverage::METERING_S
            ),
            (Method::Step(_), Colour::Unknown) => {
                " (its `u` from the residuals alone, the colour not yet metered; the runs of `host-sim study speed`)".to_string()
            }
            (Method::Model(spec), Colour::Metered) if spec.whitening > 0 => format!(
                " (the noise running {:.0} s before the landing, its block means whitened by the empty pan's noise colour metered over {:.0} s)",
                host_sim::coverage::PRE_ROLL_S,
                host_sim::coverage::METERING_S
            ),
            _ => format!(
                " (the noise running {:.0} s before the landing)",
                host_sim::coverage::PRE_ROLL_S
            ),
        };
        let header = format!(
            "Time to a final reading (2u ≤ {target_g} g with the noise level at its upper 95 % bound), `{method}` on the reference drop{how}, {runs} runs per SNR, seed {seed}; `host-sim study coverage --runs {runs} --seed {seed}`:"
        );
        if m > 0 {
            println!();
            writeln!(file)?;
        }
        final_time::write_markdown(&rows, &header, limit_g, &mut std::io::stdout().lock())?;
        final_time::write_markdown(&rows, &header, limit_g, &mut file)?;
        let title = format!(
            "{label}: time to a final reading (2u ≤ {target_g} g, noise level at its 95 % bound), {runs} runs per SNR"
        );
        final_time::write_chart(&rows, &title, &out.join(name))?;
        charts.push(name);
    }
    file.flush()?;
    println!(
        "wrote {} and the charts {}.{{svg,png}}",
        path.display(),
        charts.join(", ")
    );
    Ok(())
}

/// `study speed`: every method's speed against its accuracy.
fn study_speed(args: StudyArgs) -> Result<()> {
    let snr_db = if args.snr_db.is_empty() {
        study::SNRS_DB.to_vec()
    } else {
        args.snr_db
    };
    study::speed_command(
        args.runs.unwrap_or(1000),
        args.seed,
        &snr_db,
        args.methods,
        &args.out,
    )
}

/// `study stability`: the stability map (its own methods).
fn study_stability(args: StudyArgs) -> Result<()> {
    if !args.methods.is_empty() {
        anyhow::bail!("study stability runs its own methods; --method is for study speed");
    }
    let snr_db = if args.snr_db.is_empty() {
        host_sim::stability::SNRS_DB.to_vec()
    } else {
        args.snr_db
    };
    let orders = if args.orders.is_empty() {
        host_sim::stability::ORDERS.to_vec()
    } else {
        args.orders
    };
    host_sim::stability::stability_command(
        args.runs.unwrap_or(100),
        args.seed,
        &snr_db,
        &orders,
        args.long_samples,
        &args.out,
    )
}

/// `study ramp`: conveyor weighing on the `conveyor-ramp` scene.
fn study_ramp(args: StudyArgs) -> Result<()> {
    // The ramp study takes the regression part of `ramp:` specs (or step specs).
    let setups = args
        .methods
        .into_iter()
        .map(|method| match method {
            Method::Ramp(spec) => Ok(spec.setup),
            Method::Step(setup) => Ok(setup),
            other => Err(anyhow::anyhow!(
                "study ramp: `{other}` is not a ramp: give `ramp:n=..,D=..`"
            )),
        })
        .collect::<Result<Vec<_>>>()?;
    // The ramp's goal is at 40 dB; 30 and 50 dB show the trend.
    let snr_db = if args.snr_db.is_empty() {
        vec![30.0, 40.0, 50.0]
    } else {
        args.snr_db
    };
    host_sim::ramp_study::ramp_command(
        "conveyor-ramp",
        setups,
        &snr_db,
        args.runs.unwrap_or(1000),
        args.seed,
    )
}

fn print_calibration(
    outcome: &calibrate::Outcome,
    options: &calibrate::Options,
    out: &std::path::Path,
) {
    let c = &outcome.calibrated;
    let config = &c.config;
    let mass = options.mass_g;
    let p = &config.prediction;
    let model = &c.identified.model;
    println!(
        "identified: f_n {:.4} Hz, zeta {:.5}, gain {:.5} counts/g (fit residual {:.2} counts); noise sigma {:.3} counts ({:.4} g)",
        model.natural_frequency_hz,
        model.damping_ratio,
        config.identified_counts_per_gram,
        c.identified.noise_rms,
        config.raw_noise_variance_counts2.sqrt(),
        config.raw_noise_variance_counts2.sqrt() / config.counts_per_gram
    );
    for (index, summary) in c.drops.iter().flatten().enumerate() {
        println!(
            "  drop {index}: onset at sample {} ({:.4} s), zero {:.3} counts, noise sigma {:.3} counts",
            summary.onset,
            summary.onset as f64 / options.sample_rate_hz,
            summary.zero,
            summary.noise_variance.sqrt()
        );
    }
    println!(
        "chosen: {} (candidate {} of the ordered list; {} scored)",
        config.method, c.chosen.index, c.evaluated
    );
    println!(
        "  predicted at {} ms over {} synthetic drops: RMS {:.4} g ({:.4}%), 95th percentile {:.4} g ({:.4}%), upper bound {:.4} g ({:.4}%) <= target {:.4} g ({}%)",
        options.readout_s * 1e3,
        p.runs,
        p.rms_g,
        p.rms_g / mass * 100.0,
        p.p95_g,
        p.p95_g / mass * 100.0,
        p.p95_upper_g,
        p.p95_upper_g / mass * 100.0,
        options.target_relative * mass,
        options.target_relative * 100.0
    );
    let loads = &config.loads;
    println!(
        "  over {:.2}-{:.2} g ({} loads, platform mass {}), {} synthetic drops each:",
        loads.min_g,
        loads.max_g,
        loads.loads,
        loads
            .platform_mass_g
            .map_or("unknown: both ends".to_string(), |m| format!("{m} g")),
        c.runs_per_scene
    );
    for score in loads.scores.iter().flatten() {
        let p = &score.prediction;
        let m = score.scene.mass_g;
        println!(
            "    {:>9.4} g at {:.3}x f_n: RMS {:.4} g ({:.4}%), 95th pct {:.4}% (bound {:.4}%) <= {}%, within in {} of {}; noise floor {:.4} g ({:.4}%)",
            m,
            score.scene.frequency_ratio,
            p.rms_g,
            p.rms_g / m * 100.0,
            p.p95_g / m * 100.0,
            p.p95_upper_g / m * 100.0,
            options.target_relative * 100.0,
            p.within_target_runs,
            p.runs,
            score.noise_floor_g,
            score.noise_floor_g / m * 100.0
        );
    }
    if let Some(check) = &c.chosen.recorded {
        let errors: Vec<String> = check.errors_g[..check.drops as usize]
            .iter()
            .map(|e| format!("{e:+.4} g"))
            .collect();
        println!("  recorded drops: {}", errors.join(", "));
    }
    println!(
        "wrote {} (calibration took {:.2} s)",
        out.display(),
        outcome.elapsed_s
    );
}

fn table(runs: usize, seed: u64, snr_db: f64, readout_s: f64) -> Result<()> {
    let scene = Scene::load("reference-step")?.with_snr_db(snr_db);
    let mut setups = vec![Method::from(Setup::new(7, 1))];
    for order in [3, 4, 5, 6, 7] {
        for decimation in [4, 8, 12, 16, 24, 32] {
            setups.push(Method::from(Setup::new(order, decimation)));
        }
    }
    let study = Study {
        scene,
        setups,
        runs,
        seed,
        samples: usize::MAX,
        final_target_g: None,
    };
    let results = montecarlo::run_studies(&study, &[])?;
    let mut stdout = std::io::stdout();
    montecarlo::summary(&results, readout_s, &mut stdout)?;
    let result = &results[0];
    let k = ((readout_s * result.sample_rate_hz).round() as usize).min(result.crlb_g2.len() - 1);
    let best = result
        .setups
        .iter()
        .filter(|s| s.valid[k] as usize == runs)
        .min_by(|a, b| a.rms(k).total_cmp(&b.rms(k)));
    println!(
        "white noise {:.4e} g RMS; INA114 noise at the filter output {:.4e} g RMS",
        study.scene.disturbances.white_noise_g,
        host_sim::crlb::amplifier_autocovariance_g2(&study.scene.chain, 1)[0].sqrt()
    );
    for tolerance in [0.002, 0.001] {
        println!(
            "the sensor itself (noise-free) settles within {}% in {:.4} s",
            tolerance * 100.0,
            montecarlo::sensor_settle_time_s(&study.scene, result.truth_g, tolerance)
        );
    }
    println!(
        "CRLB at readout: {:.4e} g ({:.4e} relative)",
        result.crlb_g2[k].sqrt(),
        result.crlb_g2[k].sqrt() / result.truth_g
    );
    if let Some(best) = best {
        println!(
            "best by RMS at {} ms: {} - {:.4e} g ({:.4e} relative, {:.2}x CRLB), median time to 0.1%: {:.4} s",
            readout_s * 1e3,
            best.setup.label(),
            best.rms(k),
            best.rms(k) / result.truth_g,
            best.rms(k) / result.crlb_g2[k].sqrt(),
            best.settle_quantile(1, 0.5)
        );
    }
    Ok(())
}

fn charts(
    out: &std::path::Path,
    runs: usize,
    seed: u64,
    configs: Vec<Setup>,
    readout_s: f64,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let scene = Scene::load("reference-step")?;
    let study = Study {
        scene: scene.clone(),
        setups: configs.into_iter().map(Method::from).collect(),
        runs,
        seed,
        samples: usize::MAX,
        final_target_g: None,
    };
    let snrs = [30.0, 40.0, 50.0, 60.0, 70.0, 80.0];
    eprintln!("charts (a)–(c): {runs} runs at each of {} SNRs", snrs.len());
    let results = montecarlo::run_studies(&study, &snrs)?;
    let at_50 = results
        .iter()
        .find(|r| r.snr_db == 50.0)
        .context("no 50 dB study")?;
    chart::error_against_time(at_50).write(&out.join("a-error-vs-time"))?;
    chart::time_against_snr(&results).write(&out.join("b-time-to-accuracy-vs-snr"))?;
    chart::rms_against_snr(&results, readout_s).write(&out.join("c-rms-at-readout-vs-snr"))?;
    let readout_samples = 500;
    let order_study = Study {
        scene,
        setups: (1..=12)
            .flat_map(|order| [Setup::new(order, 1), Setup::new(order, 12)])
            .map(Method::from)
            .collect(),
        runs,
        seed,
        samples: readout_samples,
        final_target_g: None,
    };
    eprintln!("chart (d): {runs} runs, orders 1–12, D = 1 and 12, SNR 30–60 dB");
    let by_snr = montecarlo::run_studies(&order_study, &[30.0, 40.0, 50.0, 60.0])?;
    chart::mse_against_order(&by_snr, readout_samples).write(&out.join("d-mse-vs-order"))?;
    let mut summary = create(&out.join("summary.csv"))?;
    montecarlo::summary(&results, readout_s, &mut summary)?;
    summary.flush()?;
    eprintln!(
        "wrote {}/{{a,b,c,d}}-*.{{svg,png}} and summary.csv",
        out.display()
    );
    Ok(())
}

fn torture(args: TortureArgs) -> Result<()> {
    use host_sim::torture::{self, judge::Limits, TortureSettings};
    let (weighing, _precision) = match &args.config {
        Some(path) => calibrate::load_config(path)?,
        None => host_sim::replay::shipped_config()?,
    };
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let settings = TortureSettings {
        runs: args.runs,
        seed: args.seed,
        threads,
        limits: Limits {
            capacity_g: args.capacity_g.unwrap_or(weighing.capacity_g),
            scale_interval_g: args.e_g.unwrap_or(weighing.scale_interval_g),
            target_relative: weighing.target_relative,
            target_mass_g: weighing.calibration_mass_g,
        },
    };
    let tallies = match args.only_run {
        Some(run) => {
            let mut tallies = torture::judge::Tallies::default();
            let chain = host_sim::SensorChain::reference();
            let mut file = match &args.trace {
                Some(path) => {
                    Some(BufWriter::new(File::create(path).with_context(|| {
                        format!("cannot write {}", path.display())
                    })?))
                }
                None => None,
            };
            let trace = file.as_mut().map(|f| f as &mut dyn Write);
            torture::one_run(run, &settings, &chain, &weighing, &mut tallies, trace)
                .map_err(|e| anyhow::anyhow!("the weighing configuration is refused: {e}"))?;
            tallies
        }
        None => torture::torture(&settings, &weighing)
            .map_err(|e| anyhow::anyhow!("the weighing configuration is refused: {e}"))?,
    };
    print!("{}", torture::report(&settings, &tallies));
    if tallies.total().silent_wrong > 0 {
        std::process::exit(1);
    }
    Ok(())
}

fn replay(args: ReplayArgs) -> Result<()> {
    use host_sim::qemu_scenes;
    use host_sim::replay::{self, calibration, converter_samples, recorded_samples};
    if args.input.is_none() && args.recording.given() {
        anyhow::bail!("--column and --no-header describe a recording: give --input FILE.csv");
    }
    let (weighing, _precision) = match &args.config {
        Some(path) => calibrate::load_config(path)?,
        None => replay::shipped_config()?,
    };
    let (samples, (gain, zero)) = match (&args.input, args.scene.as_deref()) {
        (Some(path), _) => {
            let codes = calibrate::read_drop(path, &args.recording.layout())?;
            let rails = (weighing.onset.rail_low, weighing.onset.rail_high);
            (
                recorded_samples(&codes, rails.0, rails.1),
                (weighing.counts_per_gram, weighing.zero_counts),
            )
        }
        (None, Some(name @ ("qemu-demo" | "qemu-checked-demo"))) => {
            let mut cell = if name == "qemu-demo" {
                qemu_scenes::demo_scene()
            } else {
                qemu_scenes::checked_demo_scene()
            };
            let count = (cell.script().end_s() * host_sim::SAMPLE_RATE_HZ).round() as usize;
            let factory = qemu_scenes::factory_calibration().map_err(|e| {
                anyhow::anyhow!("the QEMU board's factory calibration failed: {e:?}")
            })?;
            (
                converter_samples(&mut cell, count),
                (
                    f64::from(factory.counts_per_gram),
                    f64::from(factory.zero_counts),
                ),
            )
        }
        (None, Some(name)) => {
            let scene = Scene::load(name)?;
            let mut adc = scene.adc(args.seed);
            (
                converter_samples(&mut adc, scene.samples()),
                (scene.chain.counts_per_gram(), scene.chain.zero_code()),
            )
        }
        (None, None) => anyhow::bail!("give --input FILE.csv or --scene NAME"),
    };
    let counts = calibration(gain, zero, args.counts_per_gram, args.zero_counts);
    let mut scale = Box::new(
        replay::ConfiguredScale::configured(&weighing, counts)
            .map_err(|e| anyhow::anyhow!("the weighing configuration is refused: {e}"))?,
    );
    let rows = replay::replay(samples, &mut scale);
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    replay::write_csv(&rows, weighing.sample_rate_hz(), &mut out)?;
    out.flush()?;
    Ok(())
}

fn monitor(args: MonitorArgs) -> Result<()> {
    use host_sim::monitor::{self, MonitorSettings};
    use std::io::{BufRead, IsTerminal};
    let input: Box<dyn BufRead + Send> = if args.input.as_os_str() == "-" {
        Box::new(BufReader::new(std::io::stdin()))
    } else {
        let file = File::open(&args.input)
            .with_context(|| format!("cannot open {}", args.input.display()))?;
        Box::new(BufReader::new(file))
    };
    let (sender, receiver) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in input.lines() {
            let Ok(line) = line else { break };
            if sender.send(line).is_err() {
                break;
            }
        }
    });
    let csv: Option<Box<dyn Write>> = match &args.csv {
        Some(path) => Some(Box::new(BufWriter::new(
            File::create(path).with_context(|| format!("cannot write {}", path.display()))?,
        ))),
        None => None,
    };
    let settings = MonitorSettings {
        window_s: args.window_s,
        sample_rate_hz: args.sample_rate_hz,
        interactive: std::io::stdout().is_terminal() && !args.text,
        text_size: (100, 24),
    };
    let csv_name = args.csv.as_ref().map(|p| p.display().to_string());
    let history = monitor::run(receiver, &settings, csv, csv_name)?;
    if !settings.interactive {
        print!(
            "{}",
            monitor::text_frame(&history, settings.window_s, settings.text_size)?
        );
    }
    Ok(())
}
