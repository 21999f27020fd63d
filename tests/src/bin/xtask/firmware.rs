//! The firmware's xtask entry points: `demo` (the QEMU firmware on the demo scene, live
//! readout and summary), `e2e_test` (the same run judged by `tests::e2e`, then the command
//! scene with the harness typing commands on UART 0, judged by `tests::commands`) and
//! `bench` (instruction counts under `-icount shift=0`, image sizes of both boards).
//!
//! The firmware logs defmt frames over semihosting to QEMU's stdout; they are decoded here
//! with `defmt-decoder` against the ELF's table, so nothing extra needs installing. For the
//! command scene QEMU's `-serial stdio` connects UART 0 to the harness's pipe: a byte
//! written to QEMU's stdin arrives in the UART's receive buffer.

use std::io::{Read, Write as _};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};
use tests::weighing_constants::CONSTANTS_VAR;

use anyhow::{anyhow, bail, Context, Result};
use tests::commands::{self, CommandScript};
use tests::console_check;
use tests::e2e::{self, RunLog, Scene};
use tests::firmware_log;
use tests::qemu::{MACHINE_ARGS, QEMU};
use tests::recording::{self, ConsoleScript, RecordScript, UploadScript};
use tests::replay_check;

use crate::util::{cargo, run_checked, target_dir, THUMB_TARGET};

/// The QEMU image's binary name.
const QEMU_BIN: &str = "firmware-qemu";
/// The STM32F411 image's binary name.
const STM32_BIN: &str = "firmware-stm32f411";
/// Flash of the STM32F411CE (the whole chip; the last 128 KiB sector holds calibration).
const STM32F411_FLASH_BYTES: u64 = 512 * 1024;
/// RAM of the STM32F411CE.
const STM32F411_RAM_BYTES: u64 = 128 * 1024;

/// Virtual time counts instructions (1 ns each); `sleep=off` skips idle time instead of
/// waiting for it, so the 4 s scene runs deterministically and as fast as the host allows.
const ICOUNT_FAST: [&str; 2] = ["-icount", "shift=0,sleep=off"];
/// Instruction-counted but idle time passes in real time: the demo's readout is live.
const ICOUNT_REAL_TIME: [&str; 2] = ["-icount", "shift=0"];
/// A run of the 4 s scene that takes longer than this hangs.
const RUN_TIMEOUT: Duration = Duration::from_secs(120);

/// `cargo xtask demo`: build the QEMU firmware, run the demo scene with a live readout,
/// then print the summary (time to 0.1 % per step, largest error once within it, drops).
pub fn demo() -> Result<()> {
    let elf = build(Board::Qemu, false)?;
    println!("==> running {} on QEMU mps2-an386 (scene: empty 0.3 s, 138.32 g, removed at 2.0 s, 250 g at 2.5 s, end 4.0 s, 50 dB)", elf.display());
    let run = run_firmware(&elf, &ICOUNT_REAL_TIME, true, None)?;
    let report = e2e::check(&Scene::demo(), &run);
    println!("\n==> summary");
    print!("{}", report.summary());
    if report.passed() {
        println!("all acceptance criteria met");
    } else {
        println!("acceptance criteria NOT met:");
        for failure in &report.failures {
            println!("  - {failure}");
        }
    }
    Ok(())
}

/// `cargo xtask monitor`: the QEMU demo in real time, its readout lines fed to host-sim's
/// monitor as they arrive (a live plot on a terminal, the last frame as text otherwise),
/// every reading logged to `target/monitor/qemu-demo.csv`.
pub fn monitor() -> Result<()> {
    use host_sim::monitor::{self, MonitorSettings};
    use std::io::IsTerminal;
    let elf = build(Board::Qemu, false)?;
    let dir = target_dir().join("monitor");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let csv_path = dir.join("qemu-demo.csv");
    let csv = std::fs::File::create(&csv_path)
        .with_context(|| format!("cannot write {}", csv_path.display()))?;
    let (sender, receiver) = mpsc::channel();
    let qemu = thread::spawn(move || {
        run_firmware_scene(
            &elf,
            &ICOUNT_REAL_TIME,
            false,
            &["demo"],
            None,
            Some(sender),
        )
    });
    let settings = MonitorSettings {
        window_s: 5.0,
        sample_rate_hz: e2e::SAMPLE_RATE_HZ,
        interactive: std::io::stdout().is_terminal(),
        text_size: (100, 24),
    };
    let history = monitor::run(
        receiver,
        &settings,
        Some(Box::new(std::io::BufWriter::new(csv))),
        Some(csv_path.display().to_string()),
    )?;
    if !settings.interactive {
        print!(
            "{}",
            monitor::text_frame(&history, settings.window_s, settings.text_size)?
        );
    }
    let run = qemu
        .join()
        .map_err(|_| anyhow!("the QEMU thread panicked"))??;
    if !run.exited_successfully {
        bail!(
            "QEMU did not end cleanly: {}",
            run.lines.last().cloned().unwrap_or_default()
        );
    }
    if history.readings.is_empty() {
        bail!("the monitor saw no reading");
    }
    println!(
        "{} readings logged to {}",
        history.readings.len(),
        csv_path.display()
    );
    Ok(())
}

/// The firmware checks of `cargo xtask test`: the STM32F411 image builds and leaves at least
/// half the chip's flash free (the firmware's size budget), the demo scene in QEMU meets the readout criteria
/// of `tests::e2e::check`, the command scene (tare, refused tare, calibration typed on
/// UART 0) meets those of `tests::commands::check`, and the checked demo (the demo after
/// 2 s more of empty pan) meters the empty pan's noise before its first drop and meets the
/// demo's criteria with the consistency check live, and the fault scenes (a stopped sample
/// timer, a stack overflow) end in the watchdog's and the fault handler's failing exits.
pub fn e2e_test() -> Result<()> {
    check_stm32_flash()?;
    let elf = build(Board::Qemu, false)?;
    check_replay_formats(&elf)?;
    e2e_demo(&elf)?;
    e2e_commands(&elf)?;
    e2e_record_loop(&elf)?;
    e2e_checked_demo(&elf)?;
    e2e_faults(&elf)?;
    e2e_bank_image()
}

/// A data-driven image has no room for a bank and links none of its code
/// (`host_sim::calibrate::firmware_constants`), so this is where the bank's firmware path is
/// built and run: the bank whose `u` holds in coloured noise (`cargo xtask bench bank-u`'s),
/// its STM32F411 image within half the flash, and its QEMU image on the demo scene reading
/// line for line what `host-sim replay` reads with the same configuration (the bank
/// configured in place at boot, its run, restarts and readings the host's).
fn e2e_bank_image() -> Result<()> {
    let shipped = shipped_config()?;
    let [.., bank] = bench_variants(&shipped)?;
    let (weighing, config) = variant_config(&shipped, &bank)?;
    let stm32 = image_size(&build_with_config(Board::Stm32f411, false, Some(&config))?)?;
    require_half_flash_free(&format!("{STM32_BIN} with {}", bank.label), stm32.flash)?;
    let run = build_with_config(Board::Qemu, false, Some(&config))
        .and_then(|elf| run_firmware(&elf, &ICOUNT_FAST, false, None));
    // Leave the QEMU image as the shipped config builds it.
    build(Board::Qemu, false)?;
    let run = run?;
    let rows = replay_check::qemu_demo_rows_with(&weighing)?;
    let mut failures = replay_check::differences(&rows, &run);
    if !run.exited_successfully {
        failures.push("QEMU did not exit successfully".to_string());
    }
    if !run
        .lines
        .iter()
        .any(|line| line.starts_with("config method=model_bank"))
    {
        failures.push("no `config method=model_bank` line".to_string());
    }
    if !failures.is_empty() {
        bail!(
            "the bank's QEMU image on the demo scene, against `host-sim replay` with its configuration:\n  - {}",
            failures.join("\n  - ")
        );
    }
    let shown = replay_check::Shown::of(&rows);
    println!(
        "the bank's QEMU image on the demo scene: all {} readout lines are the host replay's ({} with a mass, {} stable or empty, {} final)",
        rows.len(),
        shown.with_mass,
        shown.stable,
        shown.is_final
    );
    Ok(())
}

/// The failures the firmware must not survive silently: a sample clock that stops ends in
/// the watchdog's NMI, a stack overflow in a fault report; both with a failing exit and
/// their message, and neither before the scene's readout had started.
fn e2e_faults(elf: &Path) -> Result<()> {
    let cases = [
        (
            "stall",
            "the sample timer stops after 1 s",
            "ERROR watchdog: no new sample",
        ),
        (
            "stack-overflow",
            "the readout task recurses without end at 0.5 s",
            "ERROR fault: stack overflow",
        ),
    ];
    let mut failures = Vec::new();
    for (scene, what, expected) in cases {
        let run = run_firmware_scene(elf, &ICOUNT_FAST, false, &[scene], None, None)?;
        let readouts = run.readouts().len();
        let message = run.lines.iter().find(|line| line.starts_with(expected));
        println!(
            "fault scene {scene} ({what}): exit {}, {readouts} readout lines, {}",
            if run.exited_successfully {
                "0"
            } else {
                "failing"
            },
            message.map_or("no fault message", String::as_str)
        );
        if run.exited_successfully {
            failures.push(format!("{scene}: QEMU exited with status 0"));
        }
        if message.is_none() {
            failures.push(format!(
                "{scene}: no line starting `{expected}`; the run ended with:\n    {}",
                run.lines
                    .iter()
                    .rev()
                    .take(4)
                    .rev()
                    .cloned()
                    .collect::<Vec<_>>()
                    .join("\n    ")
            ));
        }
        if readouts == 0 {
            failures.push(format!("{scene}: no readout line before the fault"));
        }
    }
    require_passed("", &failures, "the firmware's fault handling")
}

/// Print a report's figures; fail with `what` and every failure unless there are none.
fn require_passed(summary: &str, failures: &[String], what: &str) -> Result<()> {
    print!("{summary}");
    if !failures.is_empty() {
        bail!("{what}:\n  - {}", failures.join("\n  - "));
    }
    Ok(())
}

/// The STM32F411 image, with either converter, leaves at least half the chip's flash free.
fn check_stm32_flash() -> Result<()> {
    for board in [Board::Stm32f411, Board::Stm32f411Ads131m02] {
        require_half_flash_free(board.label(), image_size(&build(board, false)?)?.flash)?;
    }
    Ok(())
}

/// Print an STM32F411 image's flash and fail unless half of the chip's flash is free (the
/// other half holds the calibration store).
fn require_half_flash_free(label: &str, flash: u64) -> Result<()> {
    let flash_free = 1.0 - flash as f64 / STM32F411_FLASH_BYTES as f64;
    println!(
        "{label}: {flash} B flash, {:.1} % of the STM32F411CE's flash free",
        100.0 * flash_free
    );
    if flash_free < 0.5 {
        bail!(
            "{label} uses {flash} B: less than half of the {} KiB flash is free",
            STM32F411_FLASH_BYTES / 1024
        );
    }
    Ok(())
}

/// The host replays write every line with a format string the QEMU image logs
/// (`tests::firmware_log`), letter for letter.
fn check_replay_formats(elf: &Path) -> Result<()> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let missing = firmware_log::missing_from_image(&bytes)?;
    if !missing.is_empty() {
        bail!(
            "the host replays write lines the firmware does not log (tests/src/firmware_log.rs):\n  - {}",
            missing.join("\n  - ")
        );
    }
    println!(
        "host replay formats: all {} are the firmware's",
        firmware_log::ALL.len()
    );
    Ok(())
}

/// The demo scene meets the readout criteria of `tests::e2e::check`.
fn e2e_demo(elf: &Path) -> Result<()> {
    let run = run_firmware(elf, &ICOUNT_FAST, false, None)?;
    let report = e2e::check(&Scene::demo(), &run);
    require_passed(
        &report.summary(),
        &report.failures,
        "the firmware's readout fails the acceptance criteria",
    )?;
    println!("firmware end-to-end: all criteria met");
    let rows = replay_check::qemu_demo_rows()?;
    let differences = replay_check::differences(&rows, &run);
    if !differences.is_empty() {
        bail!(
            "`host-sim replay --scene qemu-demo` differs from the QEMU firmware's readout:\n  - {}",
            differences.join("\n  - ")
        );
    }
    println!(
        "host-sim replay --scene qemu-demo: all {} rows are the QEMU firmware's readout lines",
        rows.len()
    );
    Ok(())
}

/// The command scene, the harness typing on UART 0, meets `tests::commands::check`.
fn e2e_commands(elf: &Path) -> Result<()> {
    println!(
        "command scene: the harness types on the serial console (UART 0): help, unit kg, rate 50, rate 3, method step:n=12,D=16, method step:n=7,D=1, method iv:n=7,D=16, method step:n=7,D=16, config set capacity_g 620, config show (empty pan), tare (stable), tare (sliding load), cal 200 (empty pan)"
    );
    let mut script = CommandScript::new();
    // The board's flash kept in a file, so a second run (a reset) boots with what this one
    // stored.
    let image =
        std::env::temp_dir().join(format!("fast-weighing-flash-{}.bin", std::process::id()));
    let _ = std::fs::remove_file(&image);
    let image_arg = image.to_string_lossy().into_owned();
    let scene = [commands::SCENE_NAME, image_arg.as_str()];
    let run = run_firmware_scene(elf, &ICOUNT_FAST, false, &scene, Some(&mut script), None)?;
    for line in run.lines.iter().filter(|line| line.starts_with("command ")) {
        println!("  {line}");
    }
    for line in script
        .transcript()
        .iter()
        .filter(|line| line.starts_with("OK ") || line.starts_with("ERR "))
    {
        println!("  console: {line}");
    }
    let report = commands::check(&run);
    require_passed(
        &report.summary(),
        &report.failures,
        &format!(
            "the command path fails its criteria ({} of 4 console inputs typed)",
            script.sent()
        ),
    )?;
    let console = console_check::check(script.transcript(), &run);
    require_passed(
        &console.summary(),
        &console.failures,
        "the serial console fails its criteria",
    )?;
    // A reset: the board boots again on the same flash.
    let rebooted = run_firmware_scene(elf, &ICOUNT_FAST, false, &["boot", &image_arg], None, None);
    let _ = std::fs::remove_file(&image);
    let kept = console_check::check_reset(&run, &rebooted?);
    require_passed(
        &kept.summary(),
        &kept.failures,
        "a reset does not keep the calibration and settings stored before it",
    )?;
    println!("firmware command path end-to-end: all criteria met");
    Ok(())
}

/// Record → calibrate → upload on the QEMU board (`tests::recording`): the record scene's
/// three drops recorded over the console and checked against the scene's codes,
/// `host-sim records` and `host-sim calibrate` on them as a user runs them, the chosen
/// method typed as `method <spec>` in the next run (on the same flash), which must weigh
/// the demo's drops within the demo's criteria.
fn e2e_record_loop(elf: &Path) -> Result<()> {
    println!(
        "record loop: `record` before each of 3 drops of {} g, host-sim records + calibrate, `method <spec>` in the next run",
        host_sim::qemu_scenes::RECORD_SCENE_MASS_G
    );
    let dir = crate::util::target_dir().join("record-loop");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let image = std::env::temp_dir().join(format!(
        "fast-weighing-record-flash-{}.bin",
        std::process::id()
    ));
    let _ = std::fs::remove_file(&image);
    let image_arg = image.to_string_lossy().into_owned();
    let mut script = RecordScript::new();
    let scene = [recording::SCENE_NAME, image_arg.as_str()];
    let run = run_firmware_scene(elf, &ICOUNT_FAST, false, &scene, Some(&mut script), None)?;
    if !run.exited_successfully {
        bail!(
            "the record scene did not end with status 0:\n  {}",
            run.lines.join("\n  ")
        );
    }
    let transcript = dir.join("console.txt");
    std::fs::write(&transcript, script.transcript().join("\n") + "\n")
        .with_context(|| format!("writing {}", transcript.display()))?;
    let recordings = recording::check_recordings(script.transcript(), &recording::scene_codes())
        .map_err(|failures| {
            anyhow!(
                "the board's recordings ({}) fail their criteria:\n  - {}",
                transcript.display(),
                failures.join("\n  - ")
            )
        })?;
    println!(
        "  {} recordings of {} samples, each the scene's codes from 0.25 s before the detected landing",
        recordings.len(),
        recording::RECORD_SAMPLES
    );
    let host_sim = |args: &[&str]| -> Result<String> {
        let output = crate::util::cargo()
            .args(["run", "--quiet", "-p", "host-sim", "--"])
            .args(args)
            .output()
            .context("cannot start cargo run -p host-sim")?;
        let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
        if !output.status.success() {
            bail!(
                "host-sim {} failed ({}):\n{stdout}{}",
                args.join(" "),
                output.status,
                String::from_utf8_lossy(&output.stderr)
            );
        }
        Ok(stdout)
    };
    let dir_arg = dir.to_string_lossy().into_owned();
    let transcript_arg = transcript.to_string_lossy().into_owned();
    print!(
        "{}",
        host_sim(&[
            "records",
            "--console",
            &transcript_arg,
            "--out-dir",
            &dir_arg,
            "--prefix",
            "drop"
        ])?
    );
    let drops: Vec<String> = (1..=recordings.len())
        .map(|n| {
            dir.join(format!("drop-{n}.csv"))
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let config = dir.join("weighing.toml");
    let config_arg = config.to_string_lossy().into_owned();
    let mass = host_sim::qemu_scenes::RECORD_SCENE_MASS_G.to_string();
    let mut calibrate = vec!["calibrate"];
    for drop in &drops {
        calibrate.extend(["--drop", drop.as_str()]);
    }
    calibrate.extend([
        "--mass-g",
        &mass,
        "--target-pct",
        "0.05",
        "--min-load-g",
        &mass,
        "--out",
        &config_arg,
    ]);
    let started = Instant::now();
    let chosen = host_sim(&calibrate)?;
    println!(
        "  host-sim calibrate ({:.1} s): {}",
        started.elapsed().as_secs_f64(),
        chosen.lines().next().unwrap_or("")
    );
    let toml = std::fs::read_to_string(&config)
        .with_context(|| format!("reading {}", config.display()))?;
    let spec = recording::method_spec(&toml)
        .ok_or_else(|| anyhow!("{} has no method.spec", config.display()))?;
    // Uploaded on a short run, then a reset: the demo weighs from boot with the method the
    // board stored (typed during the demo, the change would restart its first run).
    let mut upload = UploadScript::new(&spec);
    let boot = ["boot", image_arg.as_str()];
    let uploaded = run_firmware_scene(elf, &ICOUNT_FAST, false, &boot, Some(&mut upload), None);
    let demo = ["demo", image_arg.as_str()];
    let weighed =
        uploaded.and_then(|_| run_firmware_scene(elf, &ICOUNT_FAST, false, &demo, None, None));
    let _ = std::fs::remove_file(&image);
    let weighed = weighed?;
    let answer = upload.answer().unwrap_or("no answer").to_string();
    println!("  typed `method {spec}`: {answer}");
    if !answer.starts_with("OK method") || answer.contains("not stored") {
        bail!("the board did not take and store the calibrated method: {answer}");
    }
    let uploaded_spec = estimator_core::weighing::WeighingMethod::parse_spec(&spec)
        .map(|method| method.spec().to_string())
        .map_err(|error| anyhow!("{spec}: {error}"))?;
    let settings = weighed
        .lines
        .iter()
        .find(|line| line.starts_with("settings "))
        .cloned()
        .unwrap_or_default();
    println!("  after the reset: {settings}");
    if !settings.ends_with(&format!(" method={uploaded_spec}")) {
        bail!("the run after the upload logs `{settings}`, expected the settings stored with method={uploaded_spec}");
    }
    let report = e2e::check(&Scene::demo(), &weighed);
    require_passed(
        &report.summary(),
        &report.failures,
        "the demo weighed with the uploaded method fails its criteria",
    )?;
    println!("firmware record -> calibrate -> upload loop: all criteria met");
    Ok(())
}

/// The checked demo meters the empty pan's noise before its first drop and meets the
/// demo's criteria with the consistency check live.
fn e2e_checked_demo(elf: &Path) -> Result<()> {
    let scene = Scene::checked_demo();
    println!(
        "checked demo: the demo after {:.1} s more of empty pan, the consistency check live from the first drop",
        scene.loads[1].0 - Scene::demo().loads[1].0
    );
    let run = run_firmware_scene(elf, &ICOUNT_FAST, false, &["checked-demo"], None, None)?;
    let mut report = e2e::check(&scene, &run);
    let metered = run
        .lines
        .iter()
        .find_map(|line| line.strip_prefix("noise metered sample="))
        .and_then(|sample| sample.trim().parse::<u32>().ok());
    let first_drop = Scene::change_sample(scene.loads[1].0);
    match metered {
        Some(sample) if sample <= first_drop => println!(
            "  the empty pan's noise metered by sample {sample} (the first drop at {first_drop})"
        ),
        Some(sample) => report.failures.push(format!(
            "the empty pan's noise was metered only at sample {sample}, after the first drop at {first_drop}"
        )),
        None => report
            .failures
            .push("the empty pan's noise was never metered: no run was checked".to_string()),
    }
    require_passed(
        &report.summary(),
        &report.failures,
        "the checked demo fails the acceptance criteria",
    )?;
    println!("firmware checked demo end-to-end: all criteria met");
    Ok(())
}

/// `cargo xtask bench`, firmware part: instructions in the hand-off and in the estimator
/// per sample (QEMU, `-icount shift=0`) for the configured method (`firmware/weighing.toml`)
/// and for the model bank on the same calibration, and flash/RAM of the images.
pub fn bench() -> Result<()> {
    let qemu_elf = build(Board::Qemu, false)?;
    let qemu_size = image_size(&qemu_elf)?;
    let external_size = image_size(&build(Board::Stm32f411Ads131m02, false)?)?;
    let stm32_elf = build(Board::Stm32f411, false)?;
    let stm32_size = image_size(&stm32_elf)?;
    let bench_elf = build(Board::Qemu, true)?;
    println!("firmware on QEMU mps2-an386, -icount shift=0, the configured method (firmware/weighing.toml):");
    bench_run(&bench_elf, true)?;
    println!("image sizes (release, as `cargo size` counts them):");
    println!(
        "  {QEMU_BIN:<20} flash {:>7} B  RAM {:>6} B (static; the stack takes the rest)",
        qemu_size.flash, qemu_size.ram
    );
    println!(
        "  {STM32_BIN:<20} flash {:>7} B  RAM {:>6} B; STM32F411CE flash free: {:.1} % of {} KiB, RAM free {:.1} % of {} KiB",
        stm32_size.flash,
        stm32_size.ram,
        100.0 * (1.0 - stm32_size.flash as f64 / STM32F411_FLASH_BYTES as f64),
        STM32F411_FLASH_BYTES / 1024,
        100.0 * (1.0 - stm32_size.ram as f64 / STM32F411_RAM_BYTES as f64),
        STM32F411_RAM_BYTES / 1024,
    );
    println!(
        "  {:<20} flash {:>7} B  RAM {:>6} B; flash free {:.1} % (the external 24-bit converter instead of ADC1)",
        Board::Stm32f411Ads131m02.label(),
        external_size.flash,
        external_size.ram,
        100.0 * (1.0 - external_size.flash as f64 / STM32F411_FLASH_BYTES as f64),
    );

    // Other methods on the shipped file's calibration (model, noise, constants), each built as
    // a config of its own and benched the same way: the step estimator at n = 7, D = 16 (the
    // order the speed goal names, and the firmware's earlier default) and the model bank.
    let result = (|| -> Result<()> {
        let shipped = shipped_config()?;
        for variant in bench_variants(&shipped)? {
            bench_variant(&shipped, &variant)?;
        }
        Ok(())
    })();
    // Leave the images as the shipped config builds them.
    build(Board::Qemu, true)?;
    result
}

/// Which of [`bench`]'s other methods [`bench_one`] benches alone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BenchOne {
    /// `cargo xtask bench step`: the step estimator at n = 7, D = 16.
    Step,
    /// `cargo xtask bench bc`: bias-compensated least squares at the shipped n and D.
    BiasCompensated,
    /// `cargo xtask bench iv`: instrumental variables at the shipped n and D.
    InstrumentalVariable,
    /// `cargo xtask bench bank`: the model bank.
    Bank,
    /// `cargo xtask bench bank-u`: the model bank whose `u` holds in coloured noise.
    CalibratedBank,
}

/// `cargo xtask bench step` / `bc` / `iv` / `bank` / `bank-u`: only that method's line of [`bench`]
/// (its QEMU image built and run, its STM32 image's size), for a quicker loop on its cost.
pub fn bench_one(which: BenchOne) -> Result<()> {
    let result = (|| -> Result<()> {
        let shipped = shipped_config()?;
        let [step, bias_compensated, instrumental_variable, bank, calibrated_bank] =
            bench_variants(&shipped)?;
        let variant = match which {
            BenchOne::Step => step,
            BenchOne::BiasCompensated => bias_compensated,
            BenchOne::InstrumentalVariable => instrumental_variable,
            BenchOne::Bank => bank,
            BenchOne::CalibratedBank => calibrated_bank,
        };
        bench_variant(&shipped, &variant)
    })();
    // Leave the images as the shipped config builds them.
    build(Board::Qemu, true)?;
    result
}

/// Build `variant` on the shipped calibration, run its bench image and print its figures.
fn bench_variant(
    shipped: &(
        estimator_core::weighing::WeighingConfig,
        host_sim::montecarlo::Precision,
    ),
    variant: &BenchVariant,
) -> Result<()> {
    let (weighing, config) = variant_config(shipped, variant)?;
    let elf = build_with_config(Board::Qemu, true, Some(&config))?;
    let stm32 = image_size(&build_with_config(Board::Stm32f411, false, Some(&config))?)?;
    println!(
        "{} instead (built with {WEIGHING_CONFIG_VAR}={}):",
        variant.label,
        config.display()
    );
    bench_run(&elf, false)?;
    println!(
        "  {STM32_BIN:<20} with it: flash {:>7} B  RAM {:>6} B (static)",
        stm32.flash, stm32.ram
    );
    // What the scale did with it on the same scene (host replay of the same `Scale`): a cost
    // measured on a scale that shows nothing, or nothing stable, is not a weighing's cost.
    let shown = replay_check::Shown::of(&replay_check::qemu_demo_rows_with(&weighing)?);
    println!(
        "  on the demo scene (host replay): {} of {} readout lines with a mass, {} stable or empty, {} final",
        shown.with_mass, shown.lines, shown.stable, shown.is_final
    );
    Ok(())
}

/// The variable a user names another weighing configuration (TOML) with.
const WEIGHING_CONFIG_VAR: &str = "FIRMWARE_WEIGHING_CONFIG";
/// The weighing configuration of the ADS131M02 image (calibrated on drops of the simulated
/// 24-bit chain), relative to `firmware/`.
const ADS131M02_CONFIG: &str = "weighing-ads131m02.toml";
/// The weighing configuration of the STM32 image with ADC1 (calibrated on drops of the
/// simulated 12-bit board chain, `host_sim::stm32_board`), relative to `firmware/`.
const STM32_CONFIG: &str = "weighing-stm32.toml";

/// The constants of the weighing configuration `config`, generated into the target
/// directory; their path.
fn generated_constants(config: &Path) -> Result<PathBuf> {
    let source = tests::weighing_constants::generate(config, config)?;
    let dir = crate::util::target_dir().join("xtask");
    std::fs::create_dir_all(&dir).with_context(|| format!("create {}", dir.display()))?;
    let stem = config
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("weighing");
    let path = dir.join(format!("weighing-constants-{stem}.rs"));
    std::fs::write(&path, source).with_context(|| format!("write {}", path.display()))?;
    Ok(path)
}

/// The shipped `firmware/weighing.toml` and its precision.
fn shipped_config() -> Result<(
    estimator_core::weighing::WeighingConfig,
    host_sim::montecarlo::Precision,
)> {
    let shipped = crate::util::workspace_root().join("firmware/weighing.toml");
    host_sim::calibrate::load_config(&shipped)
}

/// A method benched in place of the shipped one.
struct BenchVariant {
    /// What the bench prints.
    label: String,
    /// The config file's stem under `target/xtask`.
    stem: &'static str,
    /// The method.
    method: estimator_core::weighing::WeighingMethod,
}

/// The step estimator at n = 7, D = 16, bias-compensated least squares and instrumental
/// variables at the shipped order and decimation (what `method bc:…` or `iv:…` on a board's
/// console runs on its calibration), and the model bank calibration offers
/// (`tuning::BankCandidate::REFERENCE`), widened as calibration widens it to cover the
/// shipped load range (`WeighingConfig::bank_covering_loads`), and the bank whose `u` holds
/// in coloured noise (`BankCandidate::CALIBRATED_U`: twice the grid, five-point, whitened),
/// widened the same way.
fn bench_variants(
    (shipped, _): &(
        estimator_core::weighing::WeighingConfig,
        host_sim::montecarlo::Precision,
    ),
) -> Result<[BenchVariant; 5]> {
    use estimator_core::weighing::{BankCandidate, WeighingMethod};
    let covering = |bank| {
        shipped
            .bank_covering_loads(bank)
            .context("the shipped load range gives no resonance ratios for a bank")
    };
    let (bank, calibrated_bank) = (
        covering(BankCandidate::REFERENCE)?,
        covering(BankCandidate::CALIBRATED_U)?,
    );
    // The shipped order and D; for a shipped bank, the step default's.
    let data_driven = match shipped.method.order() {
        Some(_) => shipped.method,
        None => estimator_core::weighing::ScaleConfig::DEFAULT_METHOD,
    };
    let (order, decimation) = (
        data_driven
            .order()
            .context("the step default is not a data-driven method")?,
        data_driven.decimation(),
    );
    Ok([
        BenchVariant {
            label: "the step estimator at n = 7, D = 16".to_string(),
            stem: "weighing-step-n7-d16",
            // `ScaleConfig::DEFAULT_METHOD`: the step default the decisions were measured on.
            method: estimator_core::weighing::ScaleConfig::DEFAULT_METHOD,
        },
        BenchVariant {
            label: format!("bias-compensated least squares at n = {order}, D = {decimation}"),
            stem: "weighing-bias-compensated",
            method: WeighingMethod::BiasCompensated { order, decimation },
        },
        BenchVariant {
            label: format!("instrumental variables at n = {order}, D = {decimation}"),
            stem: "weighing-instrumental-variable",
            method: WeighingMethod::InstrumentalVariable { order, decimation },
        },
        BenchVariant {
            label: "the model bank (D = 8, K = 33, covering the shipped loads' resonances)"
                .to_string(),
            stem: "weighing-model-bank",
            method: bank,
        },
        BenchVariant {
            label: "the model bank whose u holds in coloured noise (D = 8, K = 65, five-point, whitened at order 32, covering the shipped loads' resonances)"
                .to_string(),
            stem: "weighing-model-bank-u",
            method: calibrated_bank,
        },
    ])
}

/// The shipped weighing configuration with the method replaced by `variant`'s, and the path
/// it is written to under the target directory (a build input, regenerated on every bench).
fn variant_config(
    (shipped, precision): &(
        estimator_core::weighing::WeighingConfig,
        host_sim::montecarlo::Precision,
    ),
    variant: &BenchVariant,
) -> Result<(estimator_core::weighing::WeighingConfig, PathBuf)> {
    let config = estimator_core::weighing::WeighingConfig {
        method: variant.method,
        ..*shipped
    };
    let dir = target_dir().join("xtask");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("{}.toml", variant.stem));
    let text = format!(
        "# The shipped firmware/weighing.toml with {} as its method (cargo xtask bench).\n{}",
        variant.label,
        host_sim::calibrate::config_toml(&config, *precision)
    );
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok((config, path))
}

/// An exception frame with the FPU's context: 26 words, and one more to align the stack to
/// 8 bytes (ARMv7-M, "Exception entry behavior").
const EXCEPTION_FRAME_BYTES: u64 = 27 * 4;
/// RTIC's entry to a hardware task: the saved BASEPRI and the link register, pushed as a
/// pair (rtic's `export::run`); allowed for, not measured.
const RTIC_ENTRY_BYTES: u64 = 8;

/// Run a bench image and print its figures (the hand-off only when `handoff`).
fn bench_run(bench_elf: &Path, handoff: bool) -> Result<()> {
    let run = run_firmware(bench_elf, &ICOUNT_FAST, false, None)?;
    if !run.exited_successfully {
        bail!(
            "the bench firmware did not finish:\n{}",
            run.lines.join("\n")
        );
    }
    let calibration = find_fields(&run, "bench calibration")?;
    let instructions = field(&calibration, "instructions")? as f64;
    let calibration_ticks =
        field(&calibration, "long")? as f64 - field(&calibration, "short")? as f64;
    if calibration_ticks <= 0.0 {
        bail!("SysTick did not advance over the calibration loop (is -icount on?)");
    }
    let instructions_per_tick = instructions / calibration_ticks;
    let handoff_fields = find_fields(&run, "bench handoff")?;
    let estimator = find_fields(&run, "bench estimator")?;
    if field(&estimator, "dropped")? != 0 {
        bail!("the estimator replay lost samples; its count would mean nothing");
    }
    let per_event = |fields: &[(String, u64)]| -> Result<f64> {
        let events = field(fields, "events")?;
        if events == 0 {
            bail!("no events measured");
        }
        Ok(field(fields, "ticks")? as f64 / events as f64 * instructions_per_tick)
    };
    let config = run
        .lines
        .iter()
        .find(|line| line.starts_with("config "))
        .cloned()
        .ok_or_else(|| anyhow!("the bench firmware printed no `config` line"))?;
    println!("  {config}");
    println!("  SysTick: {instructions_per_tick:.2} instructions per tick (calibrated on a loop of {instructions:.0} instructions)");
    if handoff {
        println!(
            "  sample hand-off:   {:>7.1} instructions per sample incl. acknowledge and pend (goal <= 200; {} hand-offs)",
            per_event(&handoff_fields)?,
            field(&handoff_fields, "events")?
        );
    }
    println!(
        "  estimator + scale: {:>7.1} instructions per 4 kHz sample, amortised over the demo scene incl. its restarts (goal <= 1,000; {} samples)",
        per_event(&estimator)?,
        field(&estimator, "events")?
    );
    if let Ok(checked) = find_fields(&run, "bench checked") {
        if field(&checked, "dropped")? != 0 {
            bail!("the checked replay lost samples; its count would mean nothing");
        }
        // The shipped method must reach it; another method may never show the empty pan
        // stable (no `u`, or flagged), so the scale never meters it.
        let metered = field(&checked, "metered")? != 0;
        if !metered && handoff {
            bail!("the checked replay was never checked; its count would mean nothing");
        }
        let figure = if metered {
            format!(
                " (the checked demo, from its first drop on): {:>7.1} instructions per 4 kHz sample ({} samples)",
                per_event(&checked)?,
                field(&checked, "events")?
            )
        } else {
            ": never live (the scale never metered the empty pan)".to_string()
        };
        println!("  with the consistency check live{figure}");
    }
    if let Ok(coloured) = find_fields(&run, "bench coloured") {
        if field(&coloured, "dropped")? != 0 {
            bail!("the coloured replay lost samples; its count would mean nothing");
        }
        let metered = field(&coloured, "metered")? != 0;
        if !metered && handoff {
            bail!(
                "the coloured replay never metered the noise colour; its count would mean nothing"
            );
        }
        let figure = if metered {
            format!(
                " (the demo after {:.0} s of empty pan, from its first drop on): {:>7.1} instructions per 4 kHz sample ({} samples)",
                host_sim::qemu_scenes::COLOURED_DEMO_EMPTY_S,
                per_event(&coloured)?,
                field(&coloured, "events")?
            )
        } else {
            ": never live (the scale never metered enough of the empty pan)".to_string()
        };
        println!("  with the u on the metered noise colour{figure}");
    }
    if let Ok(restart) = find_fields(&run, "bench restart") {
        println!(
            "  one restart (a load change: the estimator's reset): {:.0} instructions",
            per_event(&restart)?
        );
    }
    if let Ok(stack) = find_fields(&run, "bench stack") {
        println!(
            "  stack: {} of {} B used at most (boot, factory calibration, building the scale, the replay)",
            field(&stack, "used")?,
            field(&stack, "size")?
        );
    }
    if let Ok(tasks) = find_fields(&run, "bench task stacks") {
        let size = field(&find_fields(&run, "bench stack")?, "size")?;
        let idle = field(&tasks, "idle")?;
        let handoff = field(&tasks, "handoff")?;
        let estimator = field(&tasks, "estimator")?;
        let lowest = field(&tasks, "readout")?.max(field(&tasks, "command")?);
        // Three preemptions (idle by priority 1, by 2, by 3), each stacking the FPU's
        // context (26 words, one more to align), and RTIC's entry code for each task.
        let frames = 3 * (EXCEPTION_FRAME_BYTES + RTIC_ENTRY_BYTES);
        let bound = idle + lowest + estimator + handoff + frames;
        println!(
            "  stack, worst case with preemption (QEMU board): {bound} of {size} B = idle {idle} (at most: the stack at init's entry) + readout or command {lowest} + estimator {estimator} + hand-off {handoff} (each priority's deepest, measured from init on a painted stack; the hand-off's is the simulated chain's step) + 3 × ({EXCEPTION_FRAME_BYTES} B exception frame with the FPU context + {RTIC_ENTRY_BYTES} B RTIC task entry)"
        );
        if bound > size {
            bail!("the worst-case stack ({bound} B) exceeds the stack ({size} B)");
        }
    }
    if handoff {
        if let Ok(model) = find_fields(&run, "bench model") {
            println!(
                "  (the QEMU board's simulated analogue chain, host-sim's model in soft f64, not firmware: {:.0} instructions per sample)",
                per_event(&model)?
            );
        }
    }
    Ok(())
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Board {
    Qemu,
    Stm32f411,
    /// The STM32F411 image with the ADS131M02 on SPI1 (feature `ads131m02`); the same
    /// binary name, so its ELF is the STM32 one until the next STM32 build.
    Stm32f411Ads131m02,
}

impl Board {
    /// How the image is named in the figures.
    fn label(self) -> &'static str {
        match self {
            Board::Qemu => QEMU_BIN,
            Board::Stm32f411 => STM32_BIN,
            Board::Stm32f411Ads131m02 => "firmware-stm32f411 (ads131m02)",
        }
    }
}

/// Build one firmware image in release and return its ELF.
fn build(board: Board, bench: bool) -> Result<PathBuf> {
    build_with_config(board, bench, None)
}

/// [`build`] with the weighing configuration `config` (a TOML file; else the one named by
/// `FIRMWARE_WEIGHING_CONFIG`, relative to `firmware/`; else, for an STM32 image, the one
/// calibrated on its own chain, [`STM32_CONFIG`] or [`ADS131M02_CONFIG`]; else the shipped
/// one): its constants are generated by host-sim's reader and handed to `firmware/build.rs`
/// as `FIRMWARE_WEIGHING_CONSTANTS`.
fn build_with_config(board: Board, bench: bool, config: Option<&Path>) -> Result<PathBuf> {
    let mut command = cargo();
    let chosen = match config {
        Some(config) => Some(config.to_path_buf()),
        None => std::env::var_os(WEIGHING_CONFIG_VAR)
            .map(|relative| {
                crate::util::workspace_root()
                    .join("firmware")
                    .join(relative)
            })
            // Each STM32 image weighs with the file calibrated on its own chain: the shipped
            // one is the simulated 16-bit chain's (its rails and gain are not a 12-bit or a
            // 24-bit converter's).
            .or_else(|| {
                let own = match board {
                    Board::Qemu => return None,
                    Board::Stm32f411 => STM32_CONFIG,
                    Board::Stm32f411Ads131m02 => ADS131M02_CONFIG,
                };
                Some(crate::util::workspace_root().join("firmware").join(own))
            }),
    };
    match chosen {
        Some(config) => {
            command.env(CONSTANTS_VAR, generated_constants(&config)?);
        }
        None => {
            command.env_remove(CONSTANTS_VAR);
        }
    }
    command.args([
        "build",
        "--release",
        "-p",
        "firmware",
        "--target",
        THUMB_TARGET,
    ]);
    let bin = match board {
        Board::Qemu => {
            if bench {
                command.args(["--features", "bench"]);
            }
            QEMU_BIN
        }
        Board::Stm32f411 => {
            command.args(["--no-default-features", "--features", "stm32f411"]);
            STM32_BIN
        }
        Board::Stm32f411Ads131m02 => {
            command.args(["--no-default-features", "--features", "stm32f411,ads131m02"]);
            STM32_BIN
        }
    };
    command.args(["--bin", bin]);
    run_checked(&mut command)?;
    let elf = target_dir().join(THUMB_TARGET).join("release").join(bin);
    if !elf.is_file() {
        bail!("built {bin} but found no ELF at {}", elf.display());
    }
    Ok(elf)
}

/// Run the QEMU image, decode its defmt log as it arrives (printing it when `live`), and
/// return the decoded lines with how QEMU ended. With a `script`, QEMU plays the command
/// scene, UART 0 is a socket the harness connects to, the lines the script asks for
/// after a readout line are typed on it, and what the board wrote on it is kept in the
/// script's transcript.
fn run_firmware(
    elf: &Path,
    icount: &[&str],
    live: bool,
    script: Option<&mut dyn ConsoleScript>,
) -> Result<RunLog> {
    let scene: &[&str] = if script.is_some() {
        &[commands::SCENE_NAME]
    } else {
        &["demo"]
    };
    run_firmware_scene(elf, icount, live, scene, script, None)
}

/// [`run_firmware`] on the scene and further semihosting words `scene` (the firmware's
/// `qemu::Scene` name, then a flash image file if any), each decoded line also sent to
/// `tap` as it arrives.
fn run_firmware_scene(
    elf: &Path,
    icount: &[&str],
    live: bool,
    scene: &[&str],
    mut script: Option<&mut dyn ConsoleScript>,
    tap: Option<mpsc::Sender<String>>,
) -> Result<RunLog> {
    let elf_bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let table = defmt_decoder::Table::parse(&elf_bytes)
        .context("reading the defmt table")?
        .ok_or_else(|| anyhow!("{} has no defmt data", elf.display()))?;
    let mut decoder = table.new_stream_decoder();
    let can_recover = table.encoding().can_recover();

    let socket = script.is_some().then(console_socket_path);
    let mut child = spawn_qemu(elf, icount, scene, socket.as_deref())?;
    let (mut console, console_reader) = match &socket {
        Some(path) => {
            let stream = connect_console(path, &mut child)?;
            let reader = stream.try_clone().context("the console socket")?;
            (
                Some(stream),
                Some(thread::spawn(move || read_console(reader))),
            )
        }
        None => (None, None),
    };
    let mut stdout = child
        .stdout
        .take()
        .ok_or_else(|| anyhow!("no stdout pipe"))?;
    let mut stderr = child
        .stderr
        .take()
        .ok_or_else(|| anyhow!("no stderr pipe"))?;
    let (chunks, received) = mpsc::channel::<Vec<u8>>();
    let reader = thread::spawn(move || {
        let mut buffer = [0u8; 4096];
        while let Ok(count) = stdout.read(&mut buffer) {
            if count == 0 || chunks.send(buffer[..count].to_vec()).is_err() {
                break;
            }
        }
    });
    let stderr_reader = thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });

    let started = Instant::now();
    let mut lines = Vec::new();
    let mut timed_out = false;
    loop {
        match received.recv_timeout(Duration::from_millis(50)) {
            Ok(chunk) => {
                decoder.received(&chunk);
                let mut on_line = |line: String| {
                    if let Some(tap) = &tap {
                        // A closed tap (the monitor quit) only stops the forwarding.
                        let _ = tap.send(line.clone());
                    }
                    answer_line(&line, live, script.as_deref_mut(), console.as_mut());
                    lines.push(line);
                };
                decode_lines(decoder.as_mut(), can_recover, &mut on_line);
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Err(mpsc::RecvTimeoutError::Timeout) => {}
        }
        if started.elapsed() > RUN_TIMEOUT {
            timed_out = true;
            let _ = child.kill();
            break;
        }
    }
    drop(console);
    let status = child.wait().context("waiting for QEMU")?;
    let _ = reader.join();
    if let (Some(script), Some(console_reader)) = (script, console_reader) {
        script.record_console(console_reader.join().unwrap_or_default());
    }
    if let Some(path) = &socket {
        let _ = std::fs::remove_file(path);
    }
    let qemu_stderr = stderr_reader.join().unwrap_or_default();
    if timed_out {
        lines.push(format!(
            "ERROR QEMU killed after the {} s timeout",
            RUN_TIMEOUT.as_secs()
        ));
    }
    if !status.success() && !qemu_stderr.trim().is_empty() {
        lines.push(format!("ERROR QEMU: {}", qemu_stderr.trim()));
    }
    Ok(RunLog {
        lines,
        exited_successfully: status.success() && !timed_out,
    })
}

/// A fresh path for the console's socket (in the temporary directory: a Unix socket's
/// path must stay short).
fn console_socket_path() -> PathBuf {
    let path =
        std::env::temp_dir().join(format!("fast-weighing-console-{}.sock", std::process::id()));
    let _ = std::fs::remove_file(&path);
    path
}

/// Connect to the console socket QEMU listens on (it starts the board only then).
fn connect_console(path: &Path, child: &mut Child) -> Result<UnixStream> {
    let started = Instant::now();
    loop {
        match UnixStream::connect(path) {
            Ok(stream) => return Ok(stream),
            Err(error) => {
                if let Some(status) = child.try_wait()? {
                    bail!("QEMU ended ({status}) before its console socket took a connection");
                }
                if started.elapsed() > Duration::from_secs(30) {
                    let _ = child.kill();
                    bail!(
                        "QEMU's console socket {} took no connection: {error}",
                        path.display()
                    );
                }
                thread::sleep(Duration::from_millis(20));
            }
        }
    }
}

/// Every line the board writes on its console until QEMU closes it (CR LF ends a line).
fn read_console(mut stream: UnixStream) -> Vec<String> {
    let mut bytes = Vec::new();
    let _ = stream.read_to_end(&mut bytes);
    String::from_utf8_lossy(&bytes)
        .lines()
        .map(|line| line.trim_end_matches('\r').to_string())
        .collect()
}

/// Start QEMU on `elf` with the semihosting words `scene` (the scene, then a flash image
/// file if any), its stdout and stderr piped. With a `console` socket UART 0 is that socket
/// (QEMU waits for the harness to connect before it runs the board).
fn spawn_qemu(
    elf: &Path,
    icount: &[&str],
    scene: &[&str],
    console: Option<&Path>,
) -> Result<Child> {
    let mut command = Command::new(QEMU);
    command
        .args(MACHINE_ARGS)
        .args(["-nographic", "-monitor", "none"])
        .stdin(Stdio::null());
    let mut semihosting = format!("enable=on,target=native,arg={QEMU_BIN}");
    for word in scene {
        semihosting.push_str(",arg=");
        semihosting.push_str(word);
    }
    command.args(["-semihosting-config", &semihosting]);
    if let Some(socket) = console {
        let chardev = format!(
            "socket,id=console,path={},server=on,wait=on",
            socket.display()
        );
        command.args(["-chardev", &chardev, "-serial", "chardev:console"]);
    } else {
        command.args(["-serial", "none"]);
    }
    command
        .args(icount)
        .arg("-kernel")
        .arg(elf)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot start {QEMU} (cargo xtask install)"))
}

/// Every whole frame the decoder holds, as log lines, to `on_line`; a malformed frame is
/// an `ERROR` line, and ends decoding when the encoding cannot resynchronise.
fn decode_lines(
    decoder: &mut dyn defmt_decoder::StreamDecoder,
    can_recover: bool,
    on_line: &mut dyn FnMut(String),
) {
    loop {
        match decoder.decode() {
            Ok(frame) => on_line(e2e::frame_line(&frame)),
            Err(defmt_decoder::DecodeError::UnexpectedEof) => break,
            Err(defmt_decoder::DecodeError::Malformed) => {
                on_line("ERROR malformed defmt frame".into());
                if !can_recover {
                    break;
                }
            }
        }
    }
}

/// Print `line` when `live`; after a readout line, type the lines the script asks for on
/// the console.
fn answer_line<'s>(
    line: &str,
    live: bool,
    script: Option<&mut (dyn ConsoleScript + 's)>,
    console: Option<&mut UnixStream>,
) {
    if live {
        println!("{}", pretty(line));
        let _ = std::io::stdout().flush();
    }
    let typed = match (script, e2e::ReadoutLine::parse(line)) {
        (Some(script), Some(readout)) => script.respond(&readout),
        _ => None,
    };
    if let (Some(text), Some(console)) = (typed, console) {
        // A broken pipe means QEMU is gone; how it ended is reported with the run.
        let _ = console
            .write_all(text.as_bytes())
            .and_then(|()| console.flush());
    }
}

/// A readout line as a person reads it; other lines unchanged.
fn pretty(line: &str) -> String {
    match e2e::ReadoutLine::parse(line) {
        Some(readout) => {
            let mass = readout
                .mass_g
                .map_or("     ---   ".to_string(), |mass| format!("{mass:>9.2} g"));
            format!(
                "t={:>5.2} s  {mass}  {:<12}  {:>6} samples since change  dropped {}",
                readout.time_s(),
                readout.state,
                readout.since_change,
                readout.dropped
            )
        }
        None => line.to_string(),
    }
}

/// The `key=value` fields of the first line starting with `prefix`.
fn find_fields(run: &RunLog, prefix: &str) -> Result<Vec<(String, u64)>> {
    let line = run
        .lines
        .iter()
        .find(|line| line.starts_with(prefix))
        .ok_or_else(|| anyhow!("the firmware printed no `{prefix}` line"))?;
    Ok(line
        .split_whitespace()
        .filter_map(|field| {
            let (key, value) = field.split_once('=')?;
            Some((key.to_string(), value.parse().ok()?))
        })
        .collect())
}

fn field(fields: &[(String, u64)], key: &str) -> Result<u64> {
    fields
        .iter()
        .find(|(name, _)| name == key)
        .map(|&(_, value)| value)
        .ok_or_else(|| anyhow!("no `{key}` field"))
}

/// Flash and static RAM of an image, counted like `cargo size` (`size -A`): flash is what
/// the loader writes (vector table, code, read-only data, initialised data), RAM is
/// `.data` + `.bss` + `.uninit`.
struct ImageSize {
    flash: u64,
    ram: u64,
}

fn image_size(elf: &Path) -> Result<ImageSize> {
    use object::{Object, ObjectSection};
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let file = object::File::parse(&*bytes).context("parsing the ELF")?;
    let mut size = ImageSize { flash: 0, ram: 0 };
    for section in file.sections() {
        let name = section.name().unwrap_or("");
        match name {
            ".vector_table" | ".text" | ".rodata" | ".gnu.sgstubs" => size.flash += section.size(),
            ".data" => {
                size.flash += section.size();
                size.ram += section.size();
            }
            ".bss" | ".uninit" => size.ram += section.size(),
            _ => {}
        }
    }
    if size.flash == 0 {
        bail!("{} has no code sections", elf.display());
    }
    Ok(size)
}
