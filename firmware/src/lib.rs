//! Weighing firmware (placeholder; filled by issue 4).
#![no_std]
