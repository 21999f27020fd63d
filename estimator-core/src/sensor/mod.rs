//! The sensor side: the converter seam the boards and the simulator implement
//! ([`AdcSource`]), the physical load-cell model (a mechanical mode in series with the
//! known anti-alias filter, [`LoadCellModel`]) and its identification from recorded drops
//! ([`identify()`]). Feature `ads131m02`: the driver of the external 24-bit converter on SPI
//! (`sensor::ads131m02`).
//!
//! What must never happen here: an identification that returns a model it did not fit
//! (every refusal is an [`IdentifyError`]).

mod adc;
#[cfg(feature = "ads131m02")]
pub mod ads131m02;
mod identify;
mod loadcell;

pub use adc::{AdcError, AdcSource, CodeBlock};
pub use identify::{identify, Identified, IdentifyConfig, IdentifyError};
#[cfg(test)]
pub(crate) use loadcell::reference_cell;
pub use loadcell::{LoadCellModel, MAX_DAMPING_RATIO};
