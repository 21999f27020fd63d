//! Install what a fresh machine lacks: the thumb target, `qemu-system-arm`, `flip-link`.
//! Each check is cheap, so every command runs it; it prints what it installs.

use std::path::PathBuf;
use std::process::{Command, Stdio};

use anyhow::{bail, Context, Result};

use crate::util::{run_checked, THUMB_TARGET};

/// Make sure every tool the build and the QEMU runs need is present.
pub fn ensure_tools() -> Result<()> {
    ensure_thumb_target()?;
    ensure_qemu()?;
    ensure_flip_link()?;
    Ok(())
}

fn on_path(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(program))
        .find(|candidate| candidate.is_file())
}

fn ensure_thumb_target() -> Result<()> {
    // rust-toolchain.toml names the target, so rustup normally fetched it already; a
    // toolchain installed some other way may still lack it.
    let Some(rustup) = on_path("rustup") else {
        println!("install: rustup not found; assuming the toolchain provides {THUMB_TARGET}");
        return Ok(());
    };
    let output = Command::new(&rustup)
        .args(["target", "list", "--installed"])
        .stderr(Stdio::inherit())
        .output()
        .context("run `rustup target list --installed`")?;
    let installed = String::from_utf8_lossy(&output.stdout);
    if installed.lines().any(|line| line.trim() == THUMB_TARGET) {
        return Ok(());
    }
    println!("install: rustup target add {THUMB_TARGET}");
    run_checked(Command::new(rustup).args(["target", "add", THUMB_TARGET]))
}

fn is_root() -> bool {
    // `id -u` avoids an unsafe libc call for one number.
    Command::new("id")
        .arg("-u")
        .output()
        .map(|output| String::from_utf8_lossy(&output.stdout).trim() == "0")
        .unwrap_or(false)
}

fn ensure_qemu() -> Result<()> {
    if on_path("qemu-system-arm").is_some() {
        return Ok(());
    }
    println!("install: qemu-system-arm is missing; installing it with apt-get");
    if on_path("apt-get").is_none() {
        bail!("qemu-system-arm is missing and apt-get is not available: install QEMU (ARM system emulation) by hand");
    }
    let apt = |args: &[&str]| -> Command {
        let mut command = if is_root() {
            Command::new("apt-get")
        } else {
            let mut sudo = Command::new("sudo");
            sudo.arg("apt-get");
            sudo
        };
        command
            .args(args)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .stdin(Stdio::null());
        command
    };
    run_checked(&mut apt(&["update"]))?;
    run_checked(&mut apt(&[
        "install",
        "-y",
        "--no-install-recommends",
        "qemu-system-arm",
    ]))?;
    if on_path("qemu-system-arm").is_none() {
        bail!("apt-get installed qemu-system-arm but it is not on PATH");
    }
    Ok(())
}

fn ensure_flip_link() -> Result<()> {
    // The thumb linker (`.cargo/config.toml`): puts the stack below .data/.bss.
    if on_path("flip-link").is_some() {
        return Ok(());
    }
    println!("install: cargo install flip-link --locked");
    run_checked(crate::util::cargo().args(["install", "flip-link", "--locked"]))
}
