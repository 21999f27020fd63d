//! Puts this package's `memory.x` (QEMU mps2-an386) on the linker search path and links the
//! bare-metal binaries with cortex-m-rt's `link.x`.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    // Only the binaries are linked; `-Tlink.x` is scoped to them so that no global rustflags
    // are needed (the firmware package links with its own script).
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
}
