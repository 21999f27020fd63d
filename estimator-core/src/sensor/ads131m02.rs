//! The TI ADS131M02 (24-bit, two-channel delta-sigma converter) over an embedded-hal 1.0
//! [`SpiDevice`](embedded_hal::spi::SpiDevice), behind the converter seam ([`AdcSource`]).
//!
//! Its PGA (gain up to 128) and 1.2 V internal reference take the bridge directly, in place of
//! the INA114 and the MCU's 12-bit converter; its sinc3 filter at OSR 1024 from an 8.192 MHz
//! CLKIN gives 4,000 samples a second, the rate the weighing core runs at.
//!
//! The device talks in frames: each SPI transaction shifts one command word in and one
//! response word, one word per channel and a CRC word out (24-bit words by default). The
//! response is to the command of the *previous* frame, so every command costs a frame and is
//! checked on the next one. Every frame's CRC (CRC-16-CCITT, as the device computes it) is
//! checked before a code is believed.
//!
//! What must never happen here: a code from a frame whose CRC failed, a stale conversion
//! (its DRDY bit clear) or a device that reset since it was configured reaching the caller
//! as a sample. Each is an [`Error`] (through the seam, an [`AdcError`]).
//!
//! [`AdcSource`]: crate::sensor::AdcSource
//! [`AdcError`]: crate::sensor::AdcError

mod driver;
mod frame;
mod register;
#[cfg(test)]
mod tests;

pub use driver::{Ads131m02, Config, Error};
pub use frame::{crc16_ccitt, Frame, FRAME_BYTES, FULL_SCALE_NEGATIVE, FULL_SCALE_POSITIVE};
pub use register::{Channel, Gain, Oversampling, CHANNELS, CLKIN_HZ};
