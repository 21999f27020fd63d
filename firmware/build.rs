//! Links the binaries with cortex-m-rt's and defmt's scripts against the workspace root's
//! `memory.x` (the STM32F411 board's map); for QEMU it also puts the hand-written `device.x`
//! on the search path and defines `__board_mps2_an386`, which moves the code to the AN386's
//! SSRAM at 0 (see `memory.x`).
use std::{env, fs, path::PathBuf};

fn main() {
    let qemu = env::var_os("CARGO_FEATURE_QEMU").is_some();
    let stm32 = env::var_os("CARGO_FEATURE_STM32F411").is_some();
    // Exactly one board: the crate's compile_error! says which mistake was made.
    if qemu == stm32 {
        return;
    }
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let workspace_root = manifest_dir.join("..");
    // The linker runs in the workspace root and finds `memory.x` there first; the search path
    // makes that hold even for a linker started elsewhere.
    println!("cargo:rustc-link-search={}", workspace_root.display());
    println!("cargo:rerun-if-changed=../memory.x");
    if qemu {
        let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
        fs::copy("qemu/device.x", out.join("device.x")).expect("copy device.x to OUT_DIR");
        println!("cargo:rustc-link-search={}", out.display());
        println!("cargo:rustc-link-arg-bins=--defsym=__board_mps2_an386=1");
    }
    println!("cargo:rerun-if-changed=qemu/device.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
