//! The serial console: the protocol of `estimator_core::weighing::console` on a board's
//! serial port. Bytes in become commands on the pipeline; readings and every command's
//! outcome go out as plain lines (the protocol's docs list them).
//!
//! Board-independent: a board hands in a [`SerialPort`] (the QEMU board's CMSDK UART 0, the
//! STM32's USB CDC port) and calls [`Console::receive`] for each received byte and
//! [`Console::reading`] for each reading line. Writing never blocks for long: a port that
//! stays full drops the rest of a line, counted in [`Console::lost_bytes`].
//!
//! `unit`, `rate` and `config set` change settings a reset keeps: the board's `save` stores
//! them (`estimator_core::weighing::Settings`) before the answer goes out, and an answer
//! whose change could not be stored says so (`… (until reset: not stored)`).

use core::fmt::{self, Write};

use rtic::Mutex;

use estimator_core::weighing::console::{
    parse_line, write_calibration_failure, write_error, write_method_refusal, write_outcome,
    write_reading, write_refusal, write_spec_error, ConsoleError, LineBuffer, LineEnd, ReadingLine,
    Request, Unit, MAX_LINE,
};
use estimator_core::weighing::{
    Command, CommandOutcome, CommandRefusal, RawSample, RecordRefusal, ScaleConfig, Settings,
    WeighingMethod,
};

use crate::pipeline::{self, CalibrationEnd, FirmwareRecorder, Pipeline, Readout, SAMPLE_RATE_HZ};

/// A serial port's transmit side.
pub trait SerialPort {
    /// Send `bytes`; returns how many went out (the rest were given up).
    fn write_bytes(&mut self, bytes: &[u8]) -> usize;
}

/// The commands as `help` lists them, one line each.
const HELP: [&str; 12] = [
    "tare: take the gross reading as tare",
    "untare: clear the tare",
    "zero: set the zero (stable, within 2 % of Max)",
    "cal <mass_g>: calibrate, empty pan now, then the mass on",
    "cancel: abandon a calibration",
    "unit g|kg|lb|oz: the unit of the reading lines",
    "rate <Hz>: reading lines per second (1 2 4 5 8 10 20 25 40 50 100)",
    "config show: every configuration key and its value",
    "config set <key> <value>: change one (the run restarts)",
    "method [<spec>]: the weighing method, or run another (step:n=5,D=24; the run restarts)",
    "record: the raw samples around the next load change (RECORD/D lines)",
    "help: this list",
];

/// What `raw` answers until the board streams raw samples continuously.
const NOT_BUILT: &str =
    "record (raw samples around the next load change); continuous raw streaming is not built";

/// Raw samples on one `D` line of a recording.
const RECORD_LINE_SAMPLES: usize = 16;

/// A recording being written out.
struct Dump {
    next: usize,
    len: usize,
    lost: u32,
    saturated: u32,
}

/// The console's state: the line being typed and the unit of the reading lines.
pub struct Console<P> {
    port: P,
    line: LineBuffer,
    unit: Unit,
    lost_bytes: u32,
    /// `lost_bytes` when it was last reported.
    reported_lost_bytes: u32,
    dump: Option<Dump>,
}

/// Formatting straight to the port, counting what it gave up.
struct Out<'a, P> {
    port: &'a mut P,
    lost_bytes: &'a mut u32,
}

impl<P: SerialPort> Write for Out<'_, P> {
    fn write_str(&mut self, text: &str) -> fmt::Result {
        let sent = self.port.write_bytes(text.as_bytes());
        let lost = u32::try_from(text.len() - sent).unwrap_or(u32::MAX);
        *self.lost_bytes = self.lost_bytes.saturating_add(lost);
        Ok(())
    }
}

impl<P: SerialPort> Console<P> {
    /// A console on `port`, in grams.
    pub fn new(port: P) -> Self {
        Self {
            port,
            line: LineBuffer::new(),
            unit: Unit::G,
            lost_bytes: 0,
            reported_lost_bytes: 0,
            dump: None,
        }
    }

    /// The port (its receive side is the board's).
    pub fn port(&mut self) -> &mut P {
        &mut self.port
    }

    /// Write the reading lines in `unit` from now on (the settings a reset kept).
    pub fn set_unit(&mut self, unit: Unit) {
        self.unit = unit;
    }

    /// Bytes the port gave up since boot.
    pub fn lost_bytes(&self) -> u32 {
        self.lost_bytes
    }

    /// The bytes given up since boot, when more were given up since the last call: the
    /// readout task logs them, so a port that drops lines is said in the board's log.
    pub fn newly_lost_bytes(&mut self) -> Option<u32> {
        (self.lost_bytes != self.reported_lost_bytes).then(|| {
            self.reported_lost_bytes = self.lost_bytes;
            self.lost_bytes
        })
    }

    fn count_lost(&mut self, bytes: usize) {
        let lost = u32::try_from(bytes).unwrap_or(u32::MAX);
        self.lost_bytes = self.lost_bytes.saturating_add(lost);
    }

    fn out(&mut self) -> Out<'_, P> {
        Out {
            port: &mut self.port,
            lost_bytes: &mut self.lost_bytes,
        }
    }

    /// Write the boot banner: what the console is and how to ask for help.
    pub fn banner(&mut self) {
        let _ = self
            .out()
            .write_str("# fast-weighing console: type help\r\n");
    }

    /// Take one received byte; a completed line is decided on `pipeline` and answered. A
    /// changed setting is handed to `save` first (false: it could not be stored).
    pub fn receive(
        &mut self,
        byte: u8,
        pipeline: &mut impl Mutex<T = Pipeline>,
        save: &mut impl FnMut(&Settings) -> bool,
    ) {
        let mut text = [0u8; MAX_LINE];
        let len = match self.line.push(byte) {
            None => return,
            Some(LineEnd::TooLong) => {
                let _ = write_error(&mut self.out(), "line", &ConsoleError::TooLong);
                return;
            }
            Some(LineEnd::Line(bytes)) => {
                text[..bytes.len()].copy_from_slice(bytes);
                bytes.len()
            }
        };
        let line = &text[..len];
        // The first word names the command in an answer (`line` when it is not text).
        let word = core::str::from_utf8(line)
            .ok()
            .and_then(|text| text.split_ascii_whitespace().next())
            .unwrap_or("line");
        match parse_line(line) {
            Ok(request) => self.decide(&request, pipeline, save),
            Err(error) => {
                let _ = write_error(&mut self.out(), word, &error);
            }
        }
    }

    fn decide(
        &mut self,
        request: &Request<'_>,
        pipeline: &mut impl Mutex<T = Pipeline>,
        save: &mut impl FnMut(&Settings) -> bool,
    ) {
        if let Some(command) = request.command() {
            let (sample, result, e) = pipeline.lock(|p| {
                let result = p.command(command);
                (p.samples(), result, p.scale_config().scale_interval_g)
            });
            pipeline::log_command(sample, command, &result);
            self.answer(command, &result, e);
            return;
        }
        // A setting changed: store it, then say whether that worked.
        let stored = |unit: Unit, pipeline: &mut _, save: &mut _| -> &'static str {
            if store(unit, pipeline, save) {
                ""
            } else {
                " (until reset: not stored)"
            }
        };
        let _ = match *request {
            Request::Unit(unit) => {
                self.unit = unit;
                let note = stored(unit, pipeline, save);
                write!(self.out(), "OK unit {}{note}\r\n", unit.name())
            }
            Request::Rate { hz } => {
                if pipeline.lock(|p| p.set_console_rate(hz)) {
                    let note = stored(self.unit, pipeline, save);
                    write!(self.out(), "OK rate {hz}{note}\r\n")
                } else {
                    let expected = pipeline::CONSOLE_RATES_TEXT;
                    write_error(
                        &mut self.out(),
                        "rate",
                        &ConsoleError::BadValue { expected },
                    )
                }
            }
            Request::ConfigSet { key, value } => match config_set(key, value, pipeline) {
                Ok(name) => {
                    let note = stored(self.unit, pipeline, save);
                    write!(self.out(), "OK config set {name} {value}{note}\r\n")
                }
                Err(expected) => write_error(
                    &mut self.out(),
                    "config",
                    &ConsoleError::BadValue { expected },
                ),
            },
            Request::Method { spec: Some(spec) } => match WeighingMethod::parse_spec(spec) {
                Err(error) => write_spec_error(&mut self.out(), &error),
                Ok(method) => {
                    let (sample, result) = pipeline.lock(|p| (p.samples(), p.set_method(method)));
                    pipeline::log_method(sample, &method, &result);
                    match result {
                        Ok(()) => {
                            let note = stored(self.unit, pipeline, save);
                            write!(self.out(), "OK method {}{note}\r\n", method.spec())
                        }
                        Err(refusal) => write_method_refusal(&mut self.out(), &refusal),
                    }
                }
            },
            _ => self.inform(request, pipeline),
        };
    }

    /// The requests that change nothing: answered from what the board holds.
    fn inform(
        &mut self,
        request: &Request<'_>,
        pipeline: &mut impl Mutex<T = Pipeline>,
    ) -> fmt::Result {
        let mut out = self.out();
        match *request {
            Request::Method { spec: None } => {
                let method = pipeline.lock(|p| p.method());
                write!(out, "OK method {}\r\n", method.spec())
            }
            Request::ConfigShow => {
                let (config, method) = pipeline.lock(|p| (p.scale_config(), p.method()));
                let _ = write!(out, "C method={}\r\n", method.spec());
                for field in ScaleConfig::FIELDS {
                    let value = field.get(&config);
                    if field.is_whole() {
                        let _ = write!(out, "C {}={}\r\n", field.name, value as u32);
                    } else {
                        let _ = write!(out, "C {}={}\r\n", field.name, value);
                    }
                }
                out.write_str("OK config show\r\n")
            }
            Request::Help => {
                for line in HELP {
                    let _ = write!(out, "H {line}\r\n");
                }
                out.write_str("OK help\r\n")
            }
            Request::Raw(_) => {
                let error = ConsoleError::Unavailable {
                    expected: NOT_BUILT,
                };
                write_error(&mut out, "raw", &error)
            }
            Request::Record => match pipeline.lock(|p| p.arm_record()) {
                Ok(()) => write!(
                    out,
                    "OK record armed; the next load change is recorded ({} samples, {} before it)\r\n",
                    pipeline::RECORD_SAMPLES,
                    FirmwareRecorder::BEFORE
                ),
                Err(RecordRefusal::Busy) => out.write_str(
                    "ERR record busy; expected the recording under way to end (RECORD end)\r\n",
                ),
                Err(RecordRefusal::NotBuilt) => out.write_str(
                    "ERR record unavailable; expected a board built with room for samples\r\n",
                ),
            },
            // The operator commands and the settings were decided in `decide`.
            _ => Ok(()),
        }
    }

    /// Answer an operator command, typed here or given another way (the board's KEY):
    /// `OK …` with what it did, or `ERR …` with why not (masses to the scale interval).
    pub fn answer(
        &mut self,
        command: Command,
        result: &Result<CommandOutcome, CommandRefusal>,
        scale_interval_g: f32,
    ) {
        let (unit, decimals) = (self.unit, self.unit.decimals(scale_interval_g));
        let _ = match result {
            Ok(outcome) => write_outcome(&mut self.out(), outcome, unit, decimals),
            Err(refusal) => write_refusal(&mut self.out(), command_word(command), refusal),
        };
    }

    /// Write one reading line (the readout task calls it at the console's rate, and for a
    /// final reading the moment it is reached).
    pub fn reading(&mut self, readout: &Readout, scale_interval_g: f32) {
        let line = ReadingLine {
            t_s: readout.sample as f32 / SAMPLE_RATE_HZ as f32,
            mass_g: readout.reading.mass_g,
            u_g: readout.reading.uncertainty_g,
            state: readout.reading.state,
            is_final: readout.reading.is_final,
        };
        let (unit, decimals) = (self.unit, self.unit.decimals(scale_interval_g));
        let _ = write_reading(&mut self.out(), &line, unit, decimals);
    }

    /// Write out a completed recording, at most `max_lines` lines a call (the readout task
    /// calls it every tick; a board sets the pace its port drains): `RECORD begin
    /// samples=… before=… rate_hz=…`, then `D <index> <code>…` lines of 16 samples (`L` a
    /// lost sample, `S` a saturated one), then `RECORD end samples=… lost=… saturated=…`,
    /// and the recording is given up. The pipeline is locked only to copy each line's
    /// samples, never while formatting. A line the port cut short ends the recording with
    /// `RECORD abandoned (…)` instead: the host must not take a damaged one.
    pub fn pump_record(&mut self, pipeline: &mut impl Mutex<T = Pipeline>, max_lines: usize) {
        if self.dump.is_none() {
            let Some(info) = pipeline.lock(|p| p.record_capture()) else {
                return;
            };
            let _ = write!(
                self.out(),
                "RECORD begin samples={} before={} rate_hz={}\r\n",
                info.len,
                info.change_index,
                SAMPLE_RATE_HZ
            );
            self.dump = Some(Dump {
                next: 0,
                len: info.len as usize,
                lost: 0,
                saturated: 0,
            });
        }
        for _ in 0..max_lines {
            let Some(dump) = self.dump.as_mut() else {
                return;
            };
            let start = dump.next;
            if start >= dump.len {
                let (len, lost, saturated) = (dump.len, dump.lost, dump.saturated);
                self.dump = None;
                pipeline.lock(|p| p.release_record());
                let _ = write!(
                    self.out(),
                    "RECORD end samples={len} lost={lost} saturated={saturated}\r\n"
                );
                return;
            }
            let mut samples = [RawSample::Lost; RECORD_LINE_SAMPLES];
            let count = pipeline.lock(|p| p.record_samples(start, &mut samples));
            dump.next = start + count.max(1);
            let mut line = heapless::String::<160>::new();
            let _ = write!(line, "D {start}");
            for sample in &samples[..count] {
                let _ = match sample {
                    RawSample::Counts(code) => write!(line, " {code}"),
                    RawSample::Lost => {
                        dump.lost += 1;
                        line.push_str(" L").map_err(|_| fmt::Error)
                    }
                    RawSample::Saturated => {
                        dump.saturated += 1;
                        line.push_str(" S").map_err(|_| fmt::Error)
                    }
                };
            }
            let _ = line.push_str("\r\n");
            let sent = self.port.write_bytes(line.as_bytes());
            if sent < line.len() {
                // The port dropped part of the line: the host could not trust the rest.
                self.count_lost(line.len() - sent);
                self.dump = None;
                pipeline.lock(|p| p.release_record());
                let _ = self.out().write_str(
                    "\r\nRECORD abandoned (the port dropped bytes; type record again)\r\n",
                );
                return;
            }
        }
    }

    /// Say how a calibration in progress ended.
    pub fn calibration_ended(&mut self, end: &CalibrationEnd) {
        let mut out = self.out();
        let _ = match end {
            CalibrationEnd::Applied(calibration) => write!(
                out,
                "OK cal done counts_per_g={} zero_counts={}\r\n",
                calibration.counts_per_gram, calibration.zero_counts
            ),
            CalibrationEnd::Failed(failure) => write_calibration_failure(&mut out, failure),
            CalibrationEnd::NotStored => {
                let expected = "a calibration store that writes (the calibration in use stays)";
                write_error(&mut out, "cal", &ConsoleError::Unavailable { expected })
            }
        };
    }
}

/// `config set <key> <value>`: checked with the whole configuration, then applied; the
/// key's name, or what was expected instead.
fn config_set(
    key: &str,
    value: f32,
    pipeline: &mut impl Mutex<T = Pipeline>,
) -> Result<&'static str, &'static str> {
    let field = ScaleConfig::field(key).ok_or("a configuration key (config show lists them)")?;
    if field.name == "sample_rate_hz" {
        return Err("a key the board lets change (sample_rate_hz is its converter's rate)");
    }
    pipeline
        .lock(|p| {
            let changed = field.set(&p.scale_config(), value)?;
            p.reconfigure(changed)
        })
        .map(|()| field.name)
        .map_err(|_| {
            "a value inside the key's domain (finite; positive or not negative; whole for samples)"
        })
}

/// Hand what a reset should keep to `save`.
fn store(
    unit: Unit,
    pipeline: &mut impl Mutex<T = Pipeline>,
    save: &mut impl FnMut(&Settings) -> bool,
) -> bool {
    let settings = pipeline.lock(|p| p.settings(unit));
    save(&settings)
}

/// The console word of an operator command (as typed, in the protocol's spelling).
fn command_word(command: Command) -> &'static str {
    match command {
        Command::Tare => "tare",
        Command::ClearTare => "untare",
        Command::Zero => "zero",
        Command::Calibrate { .. } => "cal",
        Command::CancelCalibration => "cancel",
    }
}
