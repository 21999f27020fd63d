//! `cargo xtask`: the project's task runner (the alias lives in `.cargo/config.toml`).
//!
//! - `cargo xtask test [all|host|target]` installs what a fresh machine lacks, then runs
//!   everything CI checks and prints a summary; it exits non-zero if any step failed.
//! - `cargo xtask demo` runs the firmware demo (see `firmware.rs`).
//! - `cargo xtask bench` prints benchmark figures (host updates/s, on-target instructions per
//!   update, estimator sizes); it asserts nothing about speed. `cargo xtask bench step`,
//!   `bench bc`, `bench iv`, `bench bank` and `bench bank-u` run only that method's on-target part.
//! - `cargo xtask install` only installs the tools.
//!
//! It must never hide a failure: every step's outcome is in the summary and the exit status.

mod bench;
mod firmware;
mod install;
mod util;

use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use util::{cargo, run_checked, THUMB_TARGET};

const USAGE: &str = "\
usage: cargo xtask <command>

commands:
  test [all|host|target]  install missing tools, then run what CI checks (default: all)
  demo                    run the firmware demo in QEMU and print the live readout
  monitor                 the QEMU demo in host-sim's live monitor (plot of mass and u, CSV log)
  bench                   print host and on-target benchmark figures and estimator sizes
  bench step              only the step estimator's at n = 7, D = 16 on-target figures
  bench bc | bench iv     only bias compensation's / instrumental variables' at the shipped n, D
  bench bank              only the model bank's on-target figures (a quicker loop)
  bench bank-u            only those of the bank whose u holds in coloured noise (K = 65)
  install                 install what a fresh machine lacks (thumb target, QEMU, flip-link)
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let result = match args.as_slice() {
        ["test"] | ["test", "all"] => test(Scope::All),
        ["test", "host"] => test(Scope::Host),
        ["test", "target"] => test(Scope::Target),
        ["demo"] => install::ensure_tools().and_then(|()| firmware::demo()),
        ["monitor"] => install::ensure_tools().and_then(|()| firmware::monitor()),
        ["bench"] => bench::run(),
        ["bench", "step"] => {
            install::ensure_tools().and_then(|()| firmware::bench_one(firmware::BenchOne::Step))
        }
        ["bench", "bc"] => install::ensure_tools()
            .and_then(|()| firmware::bench_one(firmware::BenchOne::BiasCompensated)),
        ["bench", "iv"] => install::ensure_tools()
            .and_then(|()| firmware::bench_one(firmware::BenchOne::InstrumentalVariable)),
        ["bench", "bank"] => {
            install::ensure_tools().and_then(|()| firmware::bench_one(firmware::BenchOne::Bank))
        }
        ["bench", "bank-u"] => install::ensure_tools()
            .and_then(|()| firmware::bench_one(firmware::BenchOne::CalibratedBank)),
        ["install"] => install::ensure_tools(),
        ["help"] | ["--help"] | ["-h"] => {
            print!("{USAGE}");
            Ok(())
        }
        _ => {
            eprint!("{USAGE}");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("xtask: error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

/// Which part of the checks `cargo xtask test` runs.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Scope {
    /// Formatting, host clippy, host tests (without the on-target comparison).
    Host,
    /// Thumb clippy and builds, the on-target QEMU test, the firmware end-to-end test.
    Target,
    /// Everything, as CI runs it.
    All,
}

/// The outcome of one step, for the summary.
struct StepOutcome {
    name: &'static str,
    elapsed: Duration,
    result: Result<()>,
}

/// Runs steps one after the other, keeps going after a failure (so the summary shows every
/// problem at once), and remembers each outcome.
#[derive(Default)]
struct Steps {
    outcomes: Vec<StepOutcome>,
}

impl Steps {
    fn run(&mut self, name: &'static str, step: impl FnOnce() -> Result<()>) -> bool {
        println!("\n==> {name}");
        let started = Instant::now();
        let result = step();
        let elapsed = started.elapsed();
        let ok = result.is_ok();
        match &result {
            Ok(()) => println!("<== {name}: ok ({:.1} s)", elapsed.as_secs_f64()),
            Err(error) => println!(
                "<== {name}: FAILED ({:.1} s): {error:#}",
                elapsed.as_secs_f64()
            ),
        }
        self.outcomes.push(StepOutcome {
            name,
            elapsed,
            result,
        });
        ok
    }

    /// Print the summary; `Err` if any step failed.
    fn finish(self, total: Duration) -> Result<()> {
        println!("\n==================== cargo xtask test: summary ====================");
        for outcome in &self.outcomes {
            let status = if outcome.result.is_ok() {
                "ok    "
            } else {
                "FAILED"
            };
            println!(
                "  {status} {:>7.1} s  {}",
                outcome.elapsed.as_secs_f64(),
                outcome.name
            );
        }
        let failed: Vec<&StepOutcome> =
            self.outcomes.iter().filter(|o| o.result.is_err()).collect();
        let passed = self.outcomes.len() - failed.len();
        println!("  total {:.1} s", total.as_secs_f64());
        for outcome in &failed {
            if let Err(error) = &outcome.result {
                println!("  failure in {}: {error:#}", outcome.name);
            }
        }
        // Steps, not tests: the tests are counted by cargo test's own "test result:" lines.
        println!("xtask steps: {passed} ok, {} failed", failed.len());
        if failed.is_empty() {
            Ok(())
        } else {
            bail!("{} of {} steps failed", failed.len(), self.outcomes.len())
        }
    }
}

/// `cargo xtask test`.
fn test(scope: Scope) -> Result<()> {
    let started = Instant::now();
    let mut steps = Steps::default();
    let host = matches!(scope, Scope::Host | Scope::All);
    let target = matches!(scope, Scope::Target | Scope::All);

    if !steps.run("install missing tools", install::ensure_tools) {
        // Nothing below can be trusted without the tools; report what we have.
        return steps.finish(started.elapsed());
    }
    if host {
        steps.run("cargo fmt --all -- --check", || {
            run_checked(cargo().args(["fmt", "--all", "--", "--check"]))
        });
        steps.run("cargo clippy (host crates, -D warnings)", || {
            run_checked(cargo().args(["clippy", "--all-targets", "--", "-D", "warnings"]))
        });
        // The external converter's driver is behind a feature no default member enables:
        // its clippy and its embedded-hal-mock tests run here, explicitly.
        steps.run(
            "ADS131M02 driver: clippy and mock tests (estimator-core --features ads131m02)",
            || {
                let feature = ["-p", "estimator-core", "--features", "ads131m02"];
                run_checked(cargo().arg("clippy").args(feature).args([
                    "--all-targets",
                    "--",
                    "-D",
                    "warnings",
                ]))?;
                run_checked(
                    cargo()
                        .arg("test")
                        .args(feature)
                        .args(["--lib", "sensor::ads131m02"]),
                )
            },
        );
    }
    let mut on_target_elf_dir = None;
    if target {
        steps.run("cargo clippy (thumb crates, -D warnings)", || {
            run_checked(cargo().args([
                "clippy",
                "--target",
                THUMB_TARGET,
                "-p",
                "estimator-core",
                "-p",
                "on-target",
                "-p",
                "firmware",
                "--",
                "-D",
                "warnings",
            ]))
        });
        steps.run(
            "cargo build -p estimator-core --target thumbv7em-none-eabihf",
            || {
                run_checked(cargo().args([
                    "build",
                    "-p",
                    "estimator-core",
                    "--target",
                    THUMB_TARGET,
                ]))
            },
        );
        steps.run(
            "build the on-target QEMU binaries (package on-target)",
            || {
                on_target_elf_dir = Some(util::build_on_target("core_check")?);
                Ok(())
            },
        );
    }
    if target {
        // Run on its own first, with --nocapture, so the log shows the ulp table.
        steps.run(
            "on-target tests: core_check in QEMU vs host f32 bit for bit; panic/fault exit",
            || {
                let Some(dir) = &on_target_elf_dir else {
                    bail!("the on-target ELF was not built, so the QEMU comparison could not run");
                };
                run_checked(
                    cargo()
                        .args(["test", "-p", "tests", "--test", "on_target_core_check"])
                        .args(["--", "--nocapture"])
                        .env(util::ON_TARGET_ELF_DIR_VAR, dir),
                )
            },
        );
    }
    if host {
        // All host tests of the workspace default members. With the ELF at hand (scope
        // `all`) the on-target comparison runs here again rather than skipping, so that
        // every test cargo counts as passed has really run.
        steps.run("cargo test (host tests, workspace default members)", || {
            let mut command = cargo();
            command.arg("test");
            if let Some(dir) = &on_target_elf_dir {
                command.env(util::ON_TARGET_ELF_DIR_VAR, dir);
            }
            run_checked(&mut command)
        });
    }
    if target {
        steps.run(
            "firmware end-to-end test in QEMU (firmware::e2e_test)",
            || firmware::e2e_test().context("firmware e2e test"),
        );
    }
    steps.finish(started.elapsed())
}
