//! Links the binaries with cortex-m-rt's and defmt's scripts against the workspace root's
//! `memory.x` (the STM32F411 board's map); for QEMU it also puts the hand-written `device.x`
//! on the search path and defines `__board_mps2_an386`, which moves the code to the AN386's
//! SSRAM at 0 (see `memory.x`).
//!
//! It also reads the weighing configuration, `weighing.toml` next to this file (or the file
//! named by `FIRMWARE_WEIGHING_CONFIG`, relative to this directory, e.g. for the bench of
//! another method), and writes it as Rust constants to `$OUT_DIR/weighing.rs`, which
//! `src/pipeline.rs` includes: both boards run the method calibration chose, with no
//! parsing on the target. A missing or malformed file fails the build with the file, the
//! key and what was expected.
//!
//! Why host-sim's parser (`host_sim::calibrate::firmware_constants`, a build-dependency)
//! and not a second one here or a TOML feature in `estimator-core`: that parser is the one
//! `host-sim calibrate` writes against and `host-sim estimate --config` reads with; it checks
//! every key, refuses unknown ones, cross-checks the `spec` line against host-sim's method
//! layer, and validates the values by building the configured method with the core. Moving
//! it into `estimator-core` would drag `std`, serde and toml into the `no_std` core's
//! feature set (or split the schema from the `spec` check that lives in host-sim's method
//! layer); calling it keeps exactly one implementation. The price is compile time: the
//! build script links host-sim with its `std` dependencies (built once per profile).
use std::{env, fs, path::PathBuf};

/// The weighing configuration, relative to this crate, unless `FIRMWARE_WEIGHING_CONFIG`.
const DEFAULT_CONFIG: &str = "weighing.toml";

fn main() {
    let qemu = env::var_os("CARGO_FEATURE_QEMU").is_some();
    let stm32 = env::var_os("CARGO_FEATURE_STM32F411").is_some();
    // Exactly one board: the crate's compile_error! says which mistake was made.
    if qemu == stm32 {
        return;
    }
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    weighing_config(&manifest_dir, &out);

    let workspace_root = manifest_dir.join("..");
    // The linker runs in the workspace root and finds `memory.x` there first; the search path
    // makes that hold even for a linker started elsewhere.
    println!("cargo:rustc-link-search={}", workspace_root.display());
    println!("cargo:rerun-if-changed=../memory.x");
    if qemu {
        fs::copy("qemu/device.x", out.join("device.x")).expect("copy device.x to OUT_DIR");
        println!("cargo:rustc-link-search={}", out.display());
        println!("cargo:rustc-link-arg-bins=--defsym=__board_mps2_an386=1");
    }
    println!("cargo:rerun-if-changed=qemu/device.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}

/// `weighing.toml` (or `FIRMWARE_WEIGHING_CONFIG`) to `$OUT_DIR/weighing.rs`, or a failed
/// build that says what is wrong.
fn weighing_config(manifest_dir: &std::path::Path, out: &std::path::Path) {
    println!("cargo:rerun-if-env-changed=FIRMWARE_WEIGHING_CONFIG");
    let relative = env::var("FIRMWARE_WEIGHING_CONFIG").unwrap_or_else(|_| DEFAULT_CONFIG.into());
    let path = manifest_dir.join(&relative);
    println!("cargo:rerun-if-changed={}", path.display());
    // Errors name the file as the user gave it (relative to firmware/), not the absolute path.
    let shown = PathBuf::from("firmware").join(&relative);
    let text = match fs::read_to_string(&path) {
        Ok(text) => text,
        Err(error) => fail(&format!(
            "weighing config {}: cannot read it ({error}); expected the weighing config `host-sim calibrate --out {}` writes (see firmware/README.md, \"Weighing configuration\")",
            shown.display(),
            shown.display()
        )),
    };
    match host_sim::calibrate::firmware_constants(&shown, &text) {
        Ok(source) => {
            fs::write(out.join("weighing.rs"), source).expect("write weighing.rs to OUT_DIR")
        }
        Err(error) => fail(&format!("{error:#}")),
    }
}

/// Fail the build with `message` (cargo shows a build script's stderr when it fails).
fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1)
}
