//! The driver against a scripted bus (embedded-hal-mock): the bytes of each frame out, the
//! device's frames in.

extern crate std;
use std::vec;
use std::vec::Vec;

use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};
use embedded_hal_mock::eh1::delay::NoopDelay;
use embedded_hal_mock::eh1::spi::{Mock, Transaction};

use super::frame::{command_frame, FRAME_BYTES, WORD_BYTES};
use super::*;
use crate::sensor::{AdcError, AdcSource};
use crate::weighing::RawSample;

/// STATUS of a fresh conversion on both channels, the RESET flag cleared (24-bit words).
const STATUS_READY: u16 = 0x0103;

/// The device's side of one frame: `response`, both codes, and the CRC over them.
fn device_frame(response: u16, codes: [i32; 2]) -> Vec<u8> {
    let mut frame = vec![0; FRAME_BYTES];
    frame[..2].copy_from_slice(&response.to_be_bytes());
    for (channel, code) in codes.iter().enumerate() {
        let start = WORD_BYTES * (1 + channel);
        frame[start..start + 3].copy_from_slice(&code.to_be_bytes()[1..]);
    }
    let crc = crc16_ccitt(&frame[..FRAME_BYTES - WORD_BYTES]);
    frame[FRAME_BYTES - WORD_BYTES..FRAME_BYTES - 1].copy_from_slice(&crc.to_be_bytes());
    frame
}

/// One frame on the bus as the mock expects it: the command frame out, `reply` in.
fn frame(command: u16, data: u16, reply: Vec<u8>) -> [Transaction<u8>; 3] {
    [
        Transaction::transaction_start(),
        Transaction::transfer_in_place(command_frame(command, data).to_vec(), reply),
        Transaction::transaction_end(),
    ]
}

/// The whole init sequence of a healthy device with the default config, as the data sheet
/// has it: each response answers the previous frame.
fn init_script(id: u16) -> Vec<Transaction<u8>> {
    let quiet = |response| device_frame(response, [0, 0]);
    [
        // RESET: 0x0011 in the first word, the answer predates the reset.
        frame(0x0011, 0, quiet(0x0500)),
        // RREG ID (A000h); the answer acknowledges the reset.
        frame(0xA000, 0, quiet(0xFF22)),
        // WREG MODE (6100h) = 0110h; the answer is the ID.
        frame(0x6100, 0x0110, quiet(id)),
        // WREG CLOCK (6180h) = 030Eh (both channels, OSR 1024, high resolution).
        frame(0x6180, 0x030E, quiet(0x4100)),
        // WREG GAIN1 (6200h) = 0007h (channel 0 at 128, channel 1 at 1).
        frame(0x6200, 0x0007, quiet(0x4180)),
        // RREG MODE (A100h), its write acknowledged.
        frame(0xA100, 0, quiet(0x4200)),
        frame(0xA180, 0, quiet(0x0110)),
        frame(0xA200, 0, quiet(0x030E)),
        // NULL; the answer is GAIN1's read-back.
        frame(0x0000, 0, quiet(0x0007)),
    ]
    .into_iter()
    .flatten()
    .collect()
}

/// A driver initialised on a healthy device with `config` (its registers as the default's:
/// the guard band is the driver's own), the bus scripted on with `extra`.
fn initialised_with(config: Config, extra: &[Transaction<u8>]) -> Ads131m02<Mock<u8>> {
    let mut script = init_script(0x2201);
    script.extend_from_slice(extra);
    let mut adc = Ads131m02::new(Mock::new(&script));
    adc.init(config, &mut NoopDelay::new())
        .expect("a healthy device initialises");
    adc
}

fn initialised(extra: &[Transaction<u8>]) -> Ads131m02<Mock<u8>> {
    initialised_with(Config::default(), extra)
}

fn read_null(codes: [i32; 2]) -> [Transaction<u8>; 3] {
    frame(0x0000, 0, device_frame(STATUS_READY, codes))
}

/// The CRC is CRC-16-CCITT with initial value FFFFh: its standard check value, 29B1h.
#[test]
fn crc_is_ccitt_false() {
    assert_eq!(crc16_ccitt(b"123456789"), 0x29B1);
    assert_eq!(crc16_ccitt(&[]), 0xFFFF);
}

/// A frame written out byte for byte, its CRC from an independent implementation (Python's
/// `binascii.crc_hqx(frame, 0xFFFF)`, D322h), not from this crate: the codes come out signed.
#[test]
fn a_literal_frame_is_read() {
    let reply = vec![
        0x01, 0x03, 0x00, 0x12, 0x34, 0x56, 0xFE, 0xDC, 0xBA, 0xD3, 0x22, 0x00,
    ];
    let mut adc = initialised(&frame(0x0000, 0, reply));
    let frame = adc.read_frame().unwrap();
    assert_eq!(frame.codes, [0x12_3456, 0xFE_DCBA - 0x100_0000]);
    adc.release().done();
}

/// The init sequence sends exactly the data sheet's frames (the mock fails on any other
/// byte) and consumes every one of them.
#[test]
fn init_sends_reset_id_check_writes_and_read_back() {
    let adc = initialised(&[]);
    assert_eq!(adc.config().oversampling.data_rate_hz(CLKIN_HZ), 4_000);
    adc.release().done();
}

/// A good frame: both codes and STATUS come through, and the seam reads the load-cell
/// channel as offset binary.
#[test]
fn a_good_frame_is_read() {
    let script = [read_null([123_456, -42]), read_null([123_456, -42])].concat();
    let mut adc = initialised(&script);
    let frame = adc.read_frame().unwrap();
    assert_eq!(frame.codes, [123_456, -42]);
    assert_eq!(frame.status, STATUS_READY);
    assert_eq!(adc.read(), Ok(0x80_0000 + 123_456));
    adc.release().done();
}

/// Negative codes and both full scales sign-extend from 24 bits, and map onto the seam's
/// rails.
#[test]
fn codes_sign_extend() {
    let codes = [
        [-1, 1],
        [FULL_SCALE_NEGATIVE, FULL_SCALE_POSITIVE],
        [-4_194_304, 4_194_303],
    ];
    let script: Vec<_> = codes.iter().flat_map(|&pair| read_null(pair)).collect();
    let mut adc = initialised(&script);
    for pair in codes {
        let frame = adc.read_frame().unwrap();
        assert_eq!(frame.codes, pair);
    }
    let limits = Frame {
        status: STATUS_READY,
        codes: [FULL_SCALE_NEGATIVE, FULL_SCALE_POSITIVE],
    };
    assert_eq!(limits.offset_binary(Channel::Ch0), 0);
    assert_eq!(limits.offset_binary(Channel::Ch1), (1 << 24) - 1);
    assert_eq!(adc.max_code(), (1 << 24) - 1);
    adc.release().done();
}

/// A bit flipped on the wire is a CRC error, not a code.
#[test]
fn a_corrupt_frame_is_a_crc_error() {
    let mut reply = device_frame(STATUS_READY, [1_000, 2_000]);
    reply[4] ^= 0x10;
    let mut adc = initialised(&frame(0x0000, 0, reply));
    match adc.read_frame() {
        Err(Error::Crc { computed, received }) => assert_ne!(computed, received),
        other => panic!("expected a CRC error, got {other:?}"),
    }
    adc.release().done();
}

/// A frame whose STATUS has a channel's DRDY clear is stale: `NotReady`, and the seam says
/// so too; a STATUS with the RESET flag set says the configuration is gone.
#[test]
fn stale_and_reset_frames_are_refused() {
    let script: Vec<_> = [
        frame(0x0000, 0, device_frame(0x0101, [5, 5])),
        frame(0x0000, 0, device_frame(0x0102, [5, 5])),
        frame(0x0000, 0, device_frame(0x0503, [5, 5])),
    ]
    .into_iter()
    .flatten()
    .collect();
    let mut adc = initialised(&script);
    assert_eq!(adc.read_frame(), Err(Error::NotReady { status: 0x0101 }));
    assert_eq!(adc.read(), Err(AdcError::NotReady));
    assert_eq!(
        adc.read_frame(),
        Err(Error::UnexpectedReset { status: 0x0503 })
    );
    adc.release().done();
}

/// A device that is not an ADS131M02 (an ADS131M04 answers 24xxh) is refused at init.
#[test]
fn a_wrong_id_is_refused() {
    let script: Vec<_> = init_script(0x2401).into_iter().take(9).collect();
    let mut adc = Ads131m02::new(Mock::new(&script));
    assert_eq!(
        adc.init(Config::default(), &mut NoopDelay::new()),
        Err(Error::WrongId { id: 0x2401 })
    );
    adc.release().done();
}

/// No answer to RESET (a floating MISO reads all ones, whose CRC fails; an idle device
/// answers with its STATUS) is refused.
#[test]
fn a_reset_not_acknowledged_is_refused() {
    let script: Vec<_> = [
        frame(0x0011, 0, device_frame(0x0500, [0, 0])),
        frame(0xA000, 0, device_frame(0x0500, [0, 0])),
    ]
    .into_iter()
    .flatten()
    .collect();
    let mut adc = Ads131m02::new(Mock::new(&script));
    assert_eq!(
        adc.init(Config::default(), &mut NoopDelay::new()),
        Err(Error::ResetNotAcknowledged { response: 0x0500 })
    );
    adc.release().done();
}

/// A register that reads back other than written (here CLOCK, a channel disabled) fails
/// init with the register and both values.
#[test]
fn a_wrong_read_back_is_refused() {
    let mut script = init_script(0x2201);
    // The 8th frame (index 7, sending RREG GAIN1) answers with CLOCK's read-back.
    script[7 * 3 + 1] = Transaction::transfer_in_place(
        command_frame(0xA200, 0).to_vec(),
        device_frame(0x020E, [0, 0]),
    );
    script.truncate(8 * 3);
    let mut adc = Ads131m02::new(Mock::new(&script));
    assert_eq!(
        adc.init(Config::default(), &mut NoopDelay::new()),
        Err(Error::ReadBack {
            register: 0x03,
            written: 0x030E,
            read: 0x020E
        })
    );
    adc.release().done();
}

/// A bus that fails: its own error comes back as `Error::Spi`, and through the seam the
/// sample is lost (`RawSample::Lost`), not a code.
#[test]
fn a_bus_error_propagates() {
    struct FailingBus;
    impl ErrorType for FailingBus {
        type Error = ErrorKind;
    }
    impl SpiDevice for FailingBus {
        fn transaction(&mut self, _: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
            Err(ErrorKind::Overrun)
        }
    }
    let mut adc = Ads131m02::new(FailingBus);
    assert_eq!(
        adc.init(Config::default(), &mut NoopDelay::new()),
        Err(Error::Spi(ErrorKind::Overrun))
    );
    assert_eq!(adc.read_frame(), Err(Error::Spi(ErrorKind::Overrun)));
    assert_eq!(adc.read(), Err(AdcError::Transfer));
    assert_eq!(RawSample::read(&mut adc), RawSample::Lost);
}

/// Either clip code is saturated through the seam, an ordinary code is counts (offset
/// binary); a board's guard band widens the rails.
#[test]
fn the_clip_codes_are_saturated() {
    let script: Vec<_> = [
        FULL_SCALE_POSITIVE,
        FULL_SCALE_NEGATIVE,
        FULL_SCALE_POSITIVE - 1,
        -1_000,
    ]
    .iter()
    .flat_map(|&code| read_null([code, 0]))
    .collect();
    let mut adc = initialised(&script);
    assert_eq!(RawSample::read(&mut adc), RawSample::Saturated);
    assert_eq!(RawSample::read(&mut adc), RawSample::Saturated);
    assert_eq!(RawSample::read(&mut adc), RawSample::Counts((1 << 24) - 2));
    assert_eq!(
        RawSample::read(&mut adc),
        RawSample::Counts(0x80_0000 - 1_000)
    );
    adc.release().done();

    let guarded = Config {
        rail_guard_codes: 100,
        ..Config::default()
    };
    let script: Vec<_> = [FULL_SCALE_POSITIVE - 100, FULL_SCALE_NEGATIVE + 101]
        .iter()
        .flat_map(|&code| read_null([code, 0]))
        .collect();
    let mut adc = initialised_with(guarded, &script);
    assert_eq!(RawSample::read(&mut adc), RawSample::Saturated);
    assert_eq!(RawSample::read(&mut adc), RawSample::Counts(101));
    adc.release().done();
}
