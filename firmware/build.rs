//! Puts the board's `memory.x` (`qemu/` or `stm32f411/`) (and, for QEMU, the hand-written `device.x`) on the linker
//! search path and links only the binaries with cortex-m-rt's and defmt's scripts.
use std::{env, fs, path::PathBuf};

// There is deliberately no `memory.x` at the workspace root: rustc links from the workspace
// root, and both lld (`INCLUDE memory.x`) and flip-link look in the current directory before
// the `-L` paths, so a root `memory.x` would silently replace every board's own (a QEMU image
// linked at 0x0800_0000 locks up at reset).
fn main() {
    let qemu = env::var_os("CARGO_FEATURE_QEMU").is_some();
    let stm32 = env::var_os("CARGO_FEATURE_STM32F411").is_some();
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    // Exactly one board: the crate's compile_error! says which mistake was made.
    let memory = match (qemu, stm32) {
        (true, false) => "qemu/memory.x",
        (false, true) => "stm32f411/memory.x",
        _ => return,
    };
    fs::copy(memory, out.join("memory.x")).expect("copy memory.x to OUT_DIR");
    if qemu {
        fs::copy("qemu/device.x", out.join("device.x")).expect("copy device.x to OUT_DIR");
    }
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=qemu/memory.x");
    println!("cargo:rerun-if-changed=qemu/device.x");
    println!("cargo:rerun-if-changed=stm32f411/memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
