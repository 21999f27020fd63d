//! The driver: reset and configure the device, then read one frame per DRDY.

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::SpiDevice;

use super::frame::{self, command_frame, Frame, FRAME_BYTES};
use super::register::{address, clock_value, command, gain_value, Channel, Gain, Oversampling};
use crate::sensor::{AdcError, AdcSource};

/// How the device is set up by [`Ads131m02::init`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// The sinc3 filter's oversampling ratio (OSR 1024: 4 kSPS from 8.192 MHz).
    pub oversampling: Oversampling,
    /// PGA gain of each channel.
    pub gains: [Gain; super::CHANNELS],
    /// The channel the bridge is wired to: the one the converter seam reads.
    pub load_cell_channel: Channel,
    /// Codes at each end of the range treated as saturated besides the clip codes
    /// themselves (see [`AdcSource::rail_guard_codes`]). The output clips exactly at
    /// 7FFFFFh / 800000h, so 0 suffices unless the front end clips short of full scale.
    pub rail_guard_codes: u32,
}

impl Default for Config {
    /// 4 kSPS, the bridge on channel 0 at gain 128 (±9.375 mV: a 2 mV/V cell at 3.3 V
    /// spans 6.6 mV), channel 1 at gain 1, no guard band beyond the clip codes.
    fn default() -> Self {
        Self {
            oversampling: Oversampling::Osr1024,
            gains: [Gain::G128, Gain::G1],
            load_cell_channel: Channel::Ch0,
            rail_guard_codes: 0,
        }
    }
}

/// What went wrong, with the bus's own error in [`Error::Spi`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The SPI transaction failed.
    Spi(E),
    /// The frame's CRC word does not match its contents: nothing in it is used.
    Crc {
        /// The CRC of the bytes received.
        computed: u16,
        /// The CRC word the frame carried.
        received: u16,
    },
    /// The frame after RESET did not answer FF22h: no ADS131M02 there, or the reset did
    /// not complete.
    ResetNotAcknowledged {
        /// The response word received instead.
        response: u16,
    },
    /// The ID register is not an ADS131M02's (22xxh).
    WrongId {
        /// The ID read.
        id: u16,
    },
    /// A register write was not acknowledged.
    WriteNotAcknowledged {
        /// The register's address.
        register: u8,
        /// The response word received instead of the acknowledgement.
        response: u16,
    },
    /// A register read back differs from what was written.
    ReadBack {
        /// The register's address.
        register: u8,
        /// The value written.
        written: u16,
        /// The value read back.
        read: u16,
    },
    /// A channel's DRDY bit is clear: the frame holds no new conversion (read too early,
    /// or read twice).
    NotReady {
        /// The STATUS word of the frame.
        status: u16,
    },
    /// STATUS says the device reset since [`Ads131m02::init`] (a brown-out, its RESET
    /// pin): its configuration is lost; initialise it again.
    UnexpectedReset {
        /// The STATUS word of the frame.
        status: u16,
    },
}

impl<E> Error<E> {
    /// The same error with the bus's error mapped (to log it where `E` cannot be).
    pub fn map_spi<F>(self, map: impl FnOnce(E) -> F) -> Error<F> {
        match self {
            Self::Spi(error) => Error::Spi(map(error)),
            Self::Crc { computed, received } => Error::Crc { computed, received },
            Self::ResetNotAcknowledged { response } => Error::ResetNotAcknowledged { response },
            Self::WrongId { id } => Error::WrongId { id },
            Self::WriteNotAcknowledged { register, response } => {
                Error::WriteNotAcknowledged { register, response }
            }
            Self::ReadBack {
                register,
                written,
                read,
            } => Error::ReadBack {
                register,
                written,
                read,
            },
            Self::NotReady { status } => Error::NotReady { status },
            Self::UnexpectedReset { status } => Error::UnexpectedReset { status },
        }
    }
}

/// An ADS131M02 on an SPI device (mode 1, CS framing each 12-byte frame).
#[derive(Debug)]
pub struct Ads131m02<SPI> {
    spi: SPI,
    config: Config,
}

impl<SPI: SpiDevice> Ads131m02<SPI> {
    /// The driver on `spi`; nothing is sent until [`Self::init`].
    pub fn new(spi: SPI) -> Self {
        Self {
            spi,
            config: Config::default(),
        }
    }

    /// The bus back.
    pub fn release(self) -> SPI {
        self.spi
    }

    /// The configuration in use.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Reset the device, check that it is an ADS131M02, write `config` and read every
    /// register written back. On success the next frame's response is STATUS, so
    /// [`Self::read_frame`] can follow at the next DRDY.
    pub fn init(
        &mut self,
        config: Config,
        delay: &mut impl DelayNs,
    ) -> Result<(), Error<SPI::Error>> {
        self.config = config;
        // Whatever the device answers to the RESET frame predates the reset.
        self.transfer(command::RESET, 0)?;
        // Registers can be accessed 5 µs after a reset (t_REGACQ).
        delay.delay_us(5);
        let response = self.exchange(command::read_register(address::ID), 0)?;
        if response != command::RESET_ACK {
            return Err(Error::ResetNotAcknowledged { response });
        }
        let writes = [
            (address::MODE, address::MODE_VALUE),
            (address::CLOCK, clock_value(config.oversampling)),
            (address::GAIN, gain_value(config.gains)),
        ];
        let id = self.exchange(command::write_register(writes[0].0), writes[0].1)?;
        if id & 0xFF00 != address::ID_UPPER {
            return Err(Error::WrongId { id });
        }
        // Each frame's response acknowledges the previous frame's write.
        for (index, &(register, _)) in writes.iter().enumerate() {
            let (next_command, data) = match writes.get(index + 1) {
                Some(&(next, value)) => (command::write_register(next), value),
                None => (command::read_register(writes[0].0), 0),
            };
            let response = self.exchange(next_command, data)?;
            if response != command::write_acknowledged(register) {
                return Err(Error::WriteNotAcknowledged { register, response });
            }
        }
        for (index, &(register, written)) in writes.iter().enumerate() {
            let next_command = match writes.get(index + 1) {
                Some(&(next, _)) => command::read_register(next),
                None => command::NULL,
            };
            let read = self.exchange(next_command, 0)?;
            if read != written {
                return Err(Error::ReadBack {
                    register,
                    written,
                    read,
                });
            }
        }
        Ok(())
    }

    /// Read one conversion (at DRDY low): both channels' codes and STATUS, after the CRC,
    /// the RESET flag and both DRDY bits are checked.
    pub fn read_frame(&mut self) -> Result<Frame, Error<SPI::Error>> {
        let output = self.transfer(command::NULL, 0)?;
        let output = frame::parse(&output).map_err(|mismatch| Error::Crc {
            computed: mismatch.computed,
            received: mismatch.received,
        })?;
        let status = output.response;
        if status & address::STATUS_RESET != 0 {
            return Err(Error::UnexpectedReset { status });
        }
        if address::STATUS_DRDY.iter().any(|&drdy| status & drdy == 0) {
            return Err(Error::NotReady { status });
        }
        Ok(Frame {
            status,
            codes: output.codes,
        })
    }

    /// Send `command` (with `data` in the second word) and return the response word to the
    /// previous frame's command, the frame's CRC checked.
    fn exchange(&mut self, command: u16, data: u16) -> Result<u16, Error<SPI::Error>> {
        let output = self.transfer(command, data)?;
        frame::parse(&output)
            .map(|output| output.response)
            .map_err(|mismatch| Error::Crc {
                computed: mismatch.computed,
                received: mismatch.received,
            })
    }

    /// One whole frame on the bus.
    fn transfer(
        &mut self,
        command: u16,
        data: u16,
    ) -> Result<[u8; FRAME_BYTES], Error<SPI::Error>> {
        let mut frame = command_frame(command, data);
        self.spi.transfer_in_place(&mut frame).map_err(Error::Spi)?;
        Ok(frame)
    }
}

/// The load-cell channel as the weighing core sees a converter: offset binary codes
/// 0..=2^24 − 1, so the clip codes are the rails. A stale frame is [`AdcError::NotReady`];
/// a failed transfer, a CRC mismatch or a device reset is [`AdcError::Transfer`] (call
/// [`Ads131m02::read_frame`] to tell them apart).
impl<SPI: SpiDevice> AdcSource for Ads131m02<SPI> {
    fn max_code(&self) -> u32 {
        frame::offset_binary(frame::FULL_SCALE_POSITIVE)
    }

    fn read(&mut self) -> Result<u32, AdcError> {
        match self.read_frame() {
            Ok(frame) => Ok(frame.offset_binary(self.config.load_cell_channel)),
            Err(Error::NotReady { .. }) => Err(AdcError::NotReady),
            Err(_) => Err(AdcError::Transfer),
        }
    }

    fn rail_guard_codes(&self) -> u32 {
        self.config.rail_guard_codes
    }
}
