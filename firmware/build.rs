//! Links the binaries with cortex-m-rt's and defmt's scripts against the workspace root's
//! `memory.x` (the STM32F411 board's map); for QEMU it also puts the hand-written `device.x`
//! on the search path and defines `__board_mps2_an386`, which moves the code to the AN386's
//! SSRAM at 0 (see `memory.x`).
//!
//! It also puts the weighing configuration's Rust constants where `src/pipeline.rs`
//! includes them (`$OUT_DIR/weighing.rs`): `src/weighing_config.rs`, generated from
//! `weighing.toml` by host-sim's one TOML reader and checked against it by
//! `cargo test -p tests --test weighing_constants` (which rewrites it with
//! `UPDATE_WEIGHING_CONSTANTS=1`), or the file named by `FIRMWARE_WEIGHING_CONSTANTS`, which
//! `cargo xtask` generates from another TOML file (`FIRMWARE_WEIGHING_CONFIG`) for a demo or
//! a bench of another method.
//!
//! Why a checked, generated file and not the reader itself here: the reader is host-sim's
//! (`host_sim::calibrate::firmware_constants`, the one `host-sim calibrate` writes against
//! and `estimate --config` reads with); as a build-dependency it linked all of host-sim's
//! `std` side into every firmware build. What this script must never do: build with
//! constants that do not come from that reader, or ignore a configuration it was handed.
use std::{env, fs, path::PathBuf};

/// The generated constants of `weighing.toml`, relative to this crate.
const SHIPPED_CONSTANTS: &str = "src/weighing_config.rs";
/// A generated constants file to build with instead (what `cargo xtask` hands over).
const CONSTANTS_VAR: &str = "FIRMWARE_WEIGHING_CONSTANTS";
/// A TOML file: read by `cargo xtask`, which generates the constants; refused here.
const CONFIG_VAR: &str = "FIRMWARE_WEIGHING_CONFIG";

fn main() {
    let qemu = env::var_os("CARGO_FEATURE_QEMU").is_some();
    let stm32 = env::var_os("CARGO_FEATURE_STM32F411").is_some();
    // Exactly one board: the crate's compile_error! says which mistake was made.
    if qemu == stm32 {
        return;
    }
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    weighing_constants(&manifest_dir, &out);

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

/// The shipped constants (or `FIRMWARE_WEIGHING_CONSTANTS`) to `$OUT_DIR/weighing.rs`, or a
/// failed build that says what is wrong.
fn weighing_constants(manifest_dir: &std::path::Path, out: &std::path::Path) {
    println!("cargo:rerun-if-env-changed={CONSTANTS_VAR}");
    println!("cargo:rerun-if-env-changed={CONFIG_VAR}");
    let constants = env::var_os(CONSTANTS_VAR);
    if constants.is_none() && env::var_os(CONFIG_VAR).is_some() {
        fail(&format!(
            "{CONFIG_VAR} is read by `cargo xtask` (demo, bench, test), which generates the constants from it; a plain cargo build takes the generated file in {CONSTANTS_VAR} (host_sim::calibrate::firmware_constants writes it)"
        ));
    }
    let path = match constants {
        Some(path) => PathBuf::from(path),
        None => manifest_dir.join(SHIPPED_CONSTANTS),
    };
    println!("cargo:rerun-if-changed={}", path.display());
    match fs::read_to_string(&path) {
        Ok(text) => fs::write(out.join("weighing.rs"), text).expect("write weighing.rs to OUT_DIR"),
        Err(error) => fail(&format!(
            "weighing constants {}: cannot read them ({error}); expected the file host_sim::calibrate::firmware_constants generates (see firmware/README.md, \"Weighing configuration\")",
            path.display()
        )),
    }
}

/// Fail the build with `message` (cargo shows a build script's stderr when it fails).
fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1)
}
