//! Simulator of the weighing sensor (placeholder; filled by issue 3).
#![cfg_attr(not(feature = "std"), no_std)]
