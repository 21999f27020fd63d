//! The `f32` estimator on the Cortex-M4F (QEMU mps2-an386) against the host `f32` run,
//! reading by reading, on the stored step response.
//!
//! Needs the bare-metal ELF: `cargo xtask test` builds `on-target`'s `core_check` and passes
//! its path in `ON_TARGET_CORE_CHECK_ELF`. Without that variable the test says so and skips
//! (a plain host `cargo test` cannot cross-build). With it, QEMU must be installed.
//!
//! The claim is bit-for-bit equality (0 ulp) of every estimate and residual, and equal states.
//! Why that is expected, not hoped for: the update uses only `+ − × ÷` and comparisons, which
//! IEEE 754 rounds identically on x86-64 SSE and on the M4F's FPv4-SP; rustc does not contract
//! `a·b + c` into a fused multiply-add (no fast-math), so both sides round the same operations
//! in the same order; no libm function is on the update path; and cortex-m-rt leaves the FPU
//! in its reset mode (round to nearest, no flush-to-zero, no default NaN).

use std::path::PathBuf;
use std::time::Duration;

use tests::core_check::{self, cases::CASES};
use tests::qemu;

/// The variable `cargo xtask test` sets to the `core_check` ELF.
const ELF_VAR: &str = "ON_TARGET_CORE_CHECK_ELF";

#[test]
fn target_f32_matches_host_f32_bit_for_bit() {
    let Some(elf) = std::env::var_os(ELF_VAR).map(PathBuf::from) else {
        println!(
            "SKIPPED: {ELF_VAR} is not set; `cargo xtask test` builds the on-target ELF and sets it"
        );
        return;
    };
    assert!(elf.is_file(), "{ELF_VAR}={} is not a file", elf.display());

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
