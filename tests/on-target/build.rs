//! Puts this package's `memory.x` (QEMU mps2-an386) on the linker search path and links the
//! bare-metal binaries with cortex-m-rt's `link.x`.
use std::{env, fs, path::PathBuf};

fn main() {
    // cargo runs rustc, hence the linker, in the workspace root, and the linker resolves
    // cortex-m-rt's `INCLUDE memory.x` in its working directory before any `-L` path. A
    // `memory.x` in the workspace root would silently replace ours, giving an image QEMU's
    // mps2-an386 cannot boot (nothing is mapped at 0x0800_0000). Refuse loudly instead.
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let root_memory_x = manifest_dir.join("../../memory.x");
    println!("cargo:rerun-if-changed={}", root_memory_x.display());
    if root_memory_x.exists() {
        panic!(
            "{} exists: the linker runs in the workspace root and would link that memory map \
             (a board's) into this QEMU mps2-an386 image instead of tests/on-target/memory.x. \
             Keep board memory maps inside their package (e.g. firmware/memory.x) and copy \
             them to OUT_DIR from that package's build.rs.",
            root_memory_x.display()
        );
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    // Only the binaries are linked; `-Tlink.x` is scoped to them so that no global rustflags
    // are needed (the firmware package links with its own script).
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
}
