//! The `f32` estimator on the Cortex-M4F (QEMU mps2-an386) against the host `f32` run,
//! reading by reading, on the stored step response.
//!
//! Needs the bare-metal ELFs: `cargo xtask test` builds the `on-target` package and passes
//! the directory of its ELFs in `ON_TARGET_ELF_DIR`. Without that variable the tests say so
//! and skip (a plain host `cargo test` cannot cross-build). With it, QEMU must be installed.
//!
//! Also checked here: a panic and a HardFault on the target end QEMU with a failing status,
//! which is what makes every on-target check able to fail.
//!
//! The claim is bit-for-bit equality (0 ulp) of every estimate and residual, and equal states.
//! Why that is expected, not hoped for: the update uses only `+ − × ÷` and comparisons, which
//! IEEE 754 rounds identically on x86-64 SSE and on the M4F's FPv4-SP; rustc does not contract
//! `a·b + c` into a fused multiply-add (no fast-math), so both sides round the same operations
//! in the same order (the M4F build does use `vmla.f32`/`vmls.f32`, but those round the
//! product before accumulating, unlike `vfma`: the same two roundings as `vmul` + `vadd`); no libm function is on the update path; and cortex-m-rt leaves the FPU
//! in its reset mode (round to nearest, no flush-to-zero, no default NaN).

use std::path::PathBuf;
use std::time::Duration;

use tests::core_check::{self, cases::CASES};
use tests::qemu;

/// The variable `cargo xtask test` sets to the directory of the `on-target` ELFs.
const ELF_DIR_VAR: &str = "ON_TARGET_ELF_DIR";

/// The ELF of one `on-target` binary, or `None` (with a message) when not provided.
fn on_target_elf(bin: &str) -> Option<PathBuf> {
    let Some(dir) = std::env::var_os(ELF_DIR_VAR).map(PathBuf::from) else {
        println!(
            "SKIPPED: {ELF_DIR_VAR} is not set; `cargo xtask test` builds the on-target ELFs and sets it"
        );
        return None;
    };
    let elf = dir.join(bin);
    assert!(
        elf.is_file(),
        "{ELF_DIR_VAR}: no {bin} in {}",
        dir.display()
    );
    Some(elf)
}

/// The guest `bin` ends QEMU with a failing status, not a hang, and says why with
/// `marker` (skipped without the ELFs).
fn assert_guest_fails(bin: &str, marker: &str) {
    let Some(elf) = on_target_elf(bin) else {
        return;
    };
    let run = qemu::run(&elf, &[], Duration::from_secs(30)).expect("start qemu-system-arm");
    assert!(!run.timed_out(), "{bin} hung instead of exiting");
    assert!(!run.success(), "{bin}: the guest ended QEMU with success");
    assert!(run.stdout_text().contains(marker), "{}", run.stdout_text());
}

#[test]
fn a_panic_on_the_target_fails_the_qemu_run() {
    assert_guest_fails("panic_exit", "PANIC: ");
}

#[test]
fn a_hard_fault_on_the_target_fails_the_qemu_run() {
    assert_guest_fails("fault_exit", "HARDFAULT");
}

#[test]
fn the_launcher_kills_a_run_at_its_timeout() {
    let Some(elf) = on_target_elf("core_check") else {
        return;
    };
    // QEMU cannot even start within a zero timeout, so the run must be killed and reported.
    let run = qemu::run(&elf, &[], Duration::ZERO).expect("start qemu-system-arm");
    assert!(run.timed_out(), "run ended with {:?}", run.status);
    assert!(!run.success());
    assert!(run.describe_end().contains("timeout"));
}

#[test]
fn target_f32_matches_host_f32_bit_for_bit() {
    let Some(elf) = on_target_elf("core_check") else {
        return;
    };

    let stored = std::fs::read(core_check::response_path()).expect("read the stored response");
    let host = core_check::host_records(&core_check::decode_response(&stored));

    let run = qemu::run(&elf, &[], Duration::from_secs(120)).expect("start qemu-system-arm");
    assert!(
        run.success(),
        "core_check {}; stderr: {}; last output: {}",
        run.describe_end(),
        String::from_utf8_lossy(&run.stderr),
        run.stdout_text()
            .lines()
            .rev()
            .take(3)
            .collect::<Vec<_>>()
            .join(" | ")
    );
    let target = core_check::parse_target_output(&run.stdout_text()).expect("parse core_check");
    let agreement = core_check::compare(&host, &target).expect("host and target line up");

    println!("case  n  D  lambda  readings  state-mismatch  estimate-ulp(max)  residual-ulp(max)");
    for (index, (case, result)) in CASES.iter().zip(&agreement).enumerate() {
        println!(
            "{:>4} {:>2} {:>2} {:>7} {:>9} {:>15} {:>18} {:>18}",
            index,
            case.order,
            case.decimation,
            case.forgetting,
            result.readings,
            result.state_mismatches,
            result.max_estimate_ulp,
            result.max_residual_ulp
        );
    }
    let estimating: usize = target.iter().filter(|r| r.estimate.is_some()).count();
    // The comparison is only worth something if the estimator actually estimated.
    assert!(
        estimating > target.len() / 2,
        "only {estimating} of {} readings carry an estimate",
        target.len()
    );
    for (index, result) in agreement.iter().enumerate() {
        assert_eq!(
            result.state_mismatches, 0,
            "case {index} {:?}",
            CASES[index]
        );
        assert_eq!(
            result.max_estimate_ulp, 0,
            "case {index} {:?}",
            CASES[index]
        );
        assert_eq!(
            result.max_residual_ulp, 0,
            "case {index} {:?}",
            CASES[index]
        );
    }
}
