//! Launch `qemu-system-arm` on a bare-metal ELF for the `mps2-an386` board (Cortex-M4F),
//! capture what the program prints through semihosting, and bound the run with a timeout.
//!
//! Shared by the `xtask` runner (on-target bench, firmware demo) and the host tests that
//! check on-target output. It never interprets the output: callers parse `stdout` and decide.
//! A program that panics or faults is expected to end QEMU through semihosting with a
//! non-zero status; one that hangs is killed at the timeout and reported as such.

use std::io::{self, Read};
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::thread;
use std::time::{Duration, Instant};

/// The emulator binary.
pub const QEMU: &str = "qemu-system-arm";

/// The board and CPU every on-target run uses.
pub const MACHINE_ARGS: [&str; 4] = ["-cpu", "cortex-m4", "-machine", "mps2-an386"];

/// Makes virtual time count guest instructions: one instruction = 2^0 ns. Pass it as
/// `extra_args` for instruction counts; SysTick then measures instructions, not host speed.
pub const ICOUNT_ARGS: [&str; 2] = ["-icount", "shift=0"];

/// What a QEMU run produced.
#[derive(Debug)]
pub struct QemuRun {
    /// Everything the guest wrote to the host's stdout (semihosting), as bytes.
    pub stdout: Vec<u8>,
    /// QEMU's own diagnostics.
    pub stderr: Vec<u8>,
    /// The exit status; `None` when QEMU was killed at the timeout.
    pub status: Option<ExitStatus>,
    /// Wall-clock time of the run.
    pub elapsed: Duration,
}

impl QemuRun {
    /// True when QEMU ended by itself with status 0 (the guest's semihosting exit success).
    pub fn success(&self) -> bool {
        self.status.is_some_and(|status| status.success())
    }

    /// True when the run was killed at the timeout.
    pub fn timed_out(&self) -> bool {
        self.status.is_none()
    }

    /// The captured stdout as text (lossy).
    pub fn stdout_text(&self) -> String {
        String::from_utf8_lossy(&self.stdout).into_owned()
    }

    /// A one-line description of how the run ended, for error messages.
    pub fn describe_end(&self) -> String {
        match self.status {
            None => format!(
                "killed after the {:.1} s timeout",
                self.elapsed.as_secs_f64()
            ),
            Some(status) => format!("exited with {status}"),
        }
    }
}

/// Run `elf` on `qemu-system-arm -cpu cortex-m4 -machine mps2-an386` with semihosting on,
/// no display, no serial or monitor, plus `extra_args` (e.g. [`ICOUNT_ARGS`]).
///
/// Returns an `io::Error` only when QEMU cannot be started (not installed); a guest that
/// fails or hangs is a successful call whose [`QemuRun`] says so. On timeout QEMU is killed.
pub fn run(elf: &Path, extra_args: &[&str], timeout: Duration) -> io::Result<QemuRun> {
    let started = Instant::now();
    let mut child = Command::new(QEMU)
        .args(MACHINE_ARGS)
        .args([
            "-nographic",
            "-monitor",
            "none",
            "-serial",
            "none",
            "-semihosting-config",
            "enable=on,target=native",
        ])
        .args(extra_args)
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|error| io::Error::new(error.kind(), format!("cannot start {QEMU}: {error}")))?;

    // Drain both pipes on threads so a chatty guest cannot block on a full pipe.
    let stdout_reader = drain(child.stdout.take());
    let stderr_reader = drain(child.stderr.take());

    let status = loop {
        if let Some(status) = child.try_wait()? {
            break Some(status);
        }
        if started.elapsed() >= timeout {
            // The guest hangs (or is far too slow): stop it; a kill error means it just ended.
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        thread::sleep(Duration::from_millis(10));
    };
    let stdout = stdout_reader.join().unwrap_or_default();
    let stderr = stderr_reader.join().unwrap_or_default();
    Ok(QemuRun {
        stdout,
        stderr,
        status,
        elapsed: started.elapsed(),
    })
}

fn drain<R: Read + Send + 'static>(pipe: Option<R>) -> thread::JoinHandle<Vec<u8>> {
    thread::spawn(move || {
        let mut bytes = Vec::new();
        if let Some(mut pipe) = pipe {
            let _ = pipe.read_to_end(&mut bytes);
        }
        bytes
    })
}
