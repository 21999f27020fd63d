//! The ADS131M02's commands, registers and their fields (data sheet SBAS853, "Commands" and
//! "Register Map"), and the settings a caller chooses among.

/// Channels of the ADS131M02.
pub const CHANNELS: usize = 2;

/// The CLKIN the board feeds the device (an 8.192 MHz oscillator): the data sheet's nominal
/// clock, at which the rates of [`Oversampling`] hold.
pub const CLKIN_HZ: u32 = 8_192_000;

/// Command words (16 bits, sent MSB first in the frame's first word).
pub(crate) mod command {
    /// No operation: its response is the STATUS register.
    pub const NULL: u16 = 0x0000;
    /// Reset the device (the whole frame must be clocked out).
    pub const RESET: u16 = 0x0011;
    /// The ADS131M02's answer to a completed RESET (FF2xh, x = its channel count).
    pub const RESET_ACK: u16 = 0xFF22;

    /// Read one register.
    pub const fn read_register(address: u8) -> u16 {
        0xA000 | ((address as u16 & 0x3F) << 7)
    }

    /// Write one register (its value in the frame's second word).
    pub const fn write_register(address: u8) -> u16 {
        0x6000 | ((address as u16 & 0x3F) << 7)
    }

    /// The device's acknowledgement of [`write_register`] on the next frame.
    pub const fn write_acknowledged(address: u8) -> u16 {
        0x4000 | ((address as u16 & 0x3F) << 7)
    }
}

/// Register addresses and fields.
pub(crate) mod address {
    /// ID: 22xxh on an ADS131M02 (bits 11:8 the channel count; xx the revision).
    pub const ID: u8 = 0x00;
    /// What [`ID`] reads in its upper byte.
    pub const ID_UPPER: u16 = 0x2200;
    /// MODE: word length, CRC, the RESET flag, DRDY behaviour.
    pub const MODE: u8 = 0x02;
    /// CLOCK: channel enables, OSR, power mode.
    pub const CLOCK: u8 = 0x03;
    /// GAIN1: the PGA gain of each channel.
    pub const GAIN: u8 = 0x04;

    /// MODE as written: 24-bit words, output CRC-16-CCITT, SPI timeout on, DRDY from the
    /// most lagging channel as a level, and the RESET flag cleared (reset value 0510h has it
    /// set), so a later reset shows in STATUS.
    pub const MODE_VALUE: u16 = 0x0110;

    /// STATUS: the device has reset since the RESET flag was last cleared.
    pub const STATUS_RESET: u16 = 1 << 10;
    /// STATUS: new data on channel 0 / 1.
    pub const STATUS_DRDY: [u16; super::CHANNELS] = [1 << 0, 1 << 1];
}

/// One of the two input channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Channel {
    /// AIN0P/AIN0N.
    Ch0 = 0,
    /// AIN1P/AIN1N.
    Ch1 = 1,
}

/// PGA gain: the input range is ±1.2 V / gain.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(missing_docs)] // the names are the gains
pub enum Gain {
    G1 = 0,
    G2 = 1,
    G4 = 2,
    G8 = 3,
    G16 = 4,
    G32 = 5,
    G64 = 6,
    G128 = 7,
}

impl Gain {
    /// The gain as a factor.
    pub const fn factor(self) -> u32 {
        1 << self as u32
    }
}

/// Oversampling ratio of the sinc3 filter: the data rate is CLKIN / 2 / OSR in
/// high-resolution mode (4 kSPS at OSR 1024 from 8.192 MHz).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(missing_docs)] // the names are the ratios
pub enum Oversampling {
    Osr128 = 0,
    Osr256 = 1,
    Osr512 = 2,
    Osr1024 = 3,
    Osr2048 = 4,
    Osr4096 = 5,
    Osr8192 = 6,
    /// The register description's ratio; the data-rate tables round it to 16384.
    Osr16256 = 7,
}

impl Oversampling {
    /// The ratio (modulator clocks per conversion).
    pub const fn ratio(self) -> u32 {
        match self {
            Self::Osr16256 => 16_256,
            other => 128 << other as u32,
        }
    }

    /// Conversions per second from `clkin_hz` in high-resolution mode.
    pub const fn data_rate_hz(self, clkin_hz: u32) -> u32 {
        clkin_hz / 2 / self.ratio()
    }
}

/// The CLOCK register's value: both channels on, `oversampling`, high-resolution mode.
pub(crate) const fn clock_value(oversampling: Oversampling) -> u16 {
    const BOTH_CHANNELS: u16 = 0b11 << 8;
    const HIGH_RESOLUTION: u16 = 0b10;
    BOTH_CHANNELS | ((oversampling as u16) << 2) | HIGH_RESOLUTION
}

/// The GAIN1 register's value.
pub(crate) const fn gain_value(gains: [Gain; CHANNELS]) -> u16 {
    ((gains[1] as u16) << 4) | gains[0] as u16
}
