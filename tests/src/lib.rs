//! Cross-crate and on-target tests of the weighing firmware and its estimators.

pub mod commands;
pub mod console_check;
pub mod core_check;
pub mod e2e;
pub mod firmware_log;
pub mod qemu;
pub mod recording;
pub mod replay_check;
pub mod weighing_constants;
