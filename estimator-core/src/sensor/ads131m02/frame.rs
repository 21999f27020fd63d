//! One SPI frame of the ADS131M02 in its default 24-bit word length: the command word in;
//! the response word, a word per channel and the CRC word out.

use super::register::CHANNELS;

/// Bytes in one 24-bit word.
pub(crate) const WORD_BYTES: usize = 3;
/// Words in a frame: the command or response, one per channel, the CRC.
const FRAME_WORDS: usize = 1 + CHANNELS + 1;
/// Bytes in one frame (12 in the 24-bit word length).
pub const FRAME_BYTES: usize = FRAME_WORDS * WORD_BYTES;
/// Where the CRC word starts: the CRC covers every byte before it.
const CRC_OFFSET: usize = FRAME_BYTES - WORD_BYTES;

/// The code of a positive full-scale input and beyond: the output clips here.
pub const FULL_SCALE_POSITIVE: i32 = 0x7F_FFFF;
/// The code of a negative full-scale input and beyond.
pub const FULL_SCALE_NEGATIVE: i32 = -0x80_0000;

/// One conversion of both channels, its CRC checked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame {
    /// The STATUS register as the frame reported it (the response to NULL).
    pub status: u16,
    /// Each channel's signed code, two's complement sign-extended from 24 bits:
    /// [`FULL_SCALE_NEGATIVE`]..=[`FULL_SCALE_POSITIVE`].
    pub codes: [i32; CHANNELS],
}

impl Frame {
    /// `channel`'s code as unsigned offset binary (code + 2^23): 0 at negative full scale,
    /// 2^23 at a zero input, 2^24 − 1 at positive full scale. What the converter seam
    /// carries.
    pub fn offset_binary(&self, channel: super::Channel) -> u32 {
        offset_binary(self.codes[channel as usize])
    }
}

/// A signed 24-bit code as offset binary.
pub(crate) fn offset_binary(code: i32) -> u32 {
    (code - FULL_SCALE_NEGATIVE) as u32
}

/// CRC-16-CCITT as the device computes it: polynomial 1021h, initial value FFFFh, bits MSB
/// first, no final XOR (the "CCITT-FALSE" variant).
pub fn crc16_ccitt(bytes: &[u8]) -> u16 {
    let mut crc = 0xFFFF_u16;
    for &byte in bytes {
        crc ^= (byte as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// The frame that sends `command` (and `data` in the second word, for a register write).
pub(crate) fn command_frame(command: u16, data: u16) -> [u8; FRAME_BYTES] {
    let mut frame = [0; FRAME_BYTES];
    frame[..2].copy_from_slice(&command.to_be_bytes());
    frame[WORD_BYTES..WORD_BYTES + 2].copy_from_slice(&data.to_be_bytes());
    frame
}

/// What came out of one frame, before its response is interpreted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Output {
    /// The response to the previous frame's command.
    pub response: u16,
    /// The channels' signed codes.
    pub codes: [i32; CHANNELS],
}

/// Why a frame's output is not believed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct CrcMismatch {
    pub computed: u16,
    pub received: u16,
}

/// Check the CRC of a received frame and split it into its words.
pub(crate) fn parse(frame: &[u8; FRAME_BYTES]) -> Result<Output, CrcMismatch> {
    let computed = crc16_ccitt(&frame[..CRC_OFFSET]);
    let received = u16::from_be_bytes([frame[CRC_OFFSET], frame[CRC_OFFSET + 1]]);
    if computed != received {
        return Err(CrcMismatch { computed, received });
    }
    let mut codes = [0; CHANNELS];
    for (channel, code) in codes.iter_mut().enumerate() {
        let word = &frame[WORD_BYTES * (1 + channel)..WORD_BYTES * (2 + channel)];
        // The 24-bit word in the top of an i32, shifted back down: the sign extends.
        *code = i32::from_be_bytes([word[0], word[1], word[2], 0]) >> 8;
    }
    Ok(Output {
        response: u16::from_be_bytes([frame[0], frame[1]]),
        codes,
    })
}
