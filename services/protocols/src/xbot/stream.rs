//! Finding XBot frames in the serial byte stream.
//!
//! The parser is sans-IO: [`StreamParser::push`] the bytes a read returned, then call
//! [`StreamParser::next_frame`] until it says `None` (or let [`StreamParser::feed`] do both).
//!
//! Rules:
//! * A candidate frame starts at `AA 55`; bytes before it are discarded and counted.
//! * The length byte is checked against the command id as soon as both are there: a zero length,
//!   an unknown id or a length that does not fit the id is rejected at once, without waiting for
//!   up to 255 more bytes. The sensor report's fixed markers are checked as their bytes arrive.
//! * A candidate with a bad checksum or undecodable contents is rejected too.
//! * After any rejection scanning resumes at the byte after the `AA` that started the
//!   candidate, never after its claimed length, so a good frame hidden behind or inside a bad
//!   candidate is still found.
//! * Memory is bounded: at most [`STREAM_CAPACITY`] bytes wait in the parser; pushing more
//!   without draining drops the oldest (counted as discarded). [`StreamParser::feed`] takes
//!   input of any size without overflowing.

use serde::{Deserialize, Serialize};
use std::fmt;

use super::codec::{
    FRAME_OVERHEAD, Frame, HEADER, MAX_FRAME_LEN, check_sensor_markers, checksum, decode_payload,
    id, payload_len,
};
use crate::DecodeError;
use crate::xbot::XbotProfile;

/// Most bytes a [`StreamParser`] holds (about 55 sensor reports, 0.35 s at 115200 baud).
pub const STREAM_CAPACITY: usize = 4096;

/// A rejected candidate frame: why, and its bytes as far as they were examined.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StreamError {
    pub error: DecodeError,
    /// The candidate's bytes from its `AA 55`: the header for a rejected length or id, the
    /// whole frame for a bad checksum or bad contents.
    pub raw: Vec<u8>,
}

impl fmt::Display for StreamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} in", self.error)?;
        for b in &self.raw {
            write!(f, " {b:02X}")?;
        }
        Ok(())
    }
}

impl std::error::Error for StreamError {}

/// Incremental XBot frame parser; see the module docs for its rules.
#[derive(Debug, Default, Serialize, Deserialize)]
pub struct StreamParser {
    /// Received bytes; those before `start` are consumed (dropped on the next push, so a
    /// rejection costs no copying).
    buf: Vec<u8>,
    start: usize,
    bytes_discarded: u64,
    frames: u64,
    errors: u64,
}

impl StreamParser {
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes. Call [`Self::next_frame`] until `None` afterwards; beyond
    /// [`STREAM_CAPACITY`] waiting bytes the oldest are dropped.
    pub fn push(&mut self, bytes: &[u8]) {
        self.compact();
        self.buf.extend_from_slice(bytes);
        if self.buf.len() > STREAM_CAPACITY {
            let excess = self.buf.len() - STREAM_CAPACITY;
            self.discard(excess);
            self.compact();
        }
    }

    /// The next frame or rejected candidate, in stream order; `None` when more bytes are needed.
    pub fn next_frame(&mut self, profile: &XbotProfile) -> Option<Result<Frame, StreamError>> {
        self.skip_to_header();
        let data = &self.buf[self.start..];
        let len = *data.get(2)?;
        if len == 0 {
            let error = DecodeError::TooShort {
                id: 0,
                len: 0,
                need: 1,
            };
            return Some(Err(self.reject(3, error)));
        }
        let command = *data.get(3)?;
        let Some(expected) = payload_len(command) else {
            let error = DecodeError::UnknownId { id: command.into() };
            return Some(Err(self.reject(4, error)));
        };
        if usize::from(len) != expected {
            let error = DecodeError::BadLength {
                command,
                len: len.into(),
                expected,
            };
            return Some(Err(self.reject(4, error)));
        }
        let total = expected + FRAME_OVERHEAD;
        if command == id::SENSOR {
            let present = &data[3..data.len().min(total - 1)];
            if let Err(error) = check_sensor_markers(present) {
                let examined = data.len().min(total);
                return Some(Err(self.reject(examined, error)));
            }
        }
        let frame = data.get(..total)?;
        let payload = &frame[3..total - 1];
        let got = frame[total - 1];
        let want = checksum(len, payload);
        if got != want {
            let error = DecodeError::BadChecksum {
                expected: want,
                got,
            };
            return Some(Err(self.reject(total, error)));
        }
        match decode_payload(payload, profile) {
            Ok(frame) => {
                self.start += total;
                self.frames += 1;
                Some(Ok(frame))
            }
            Err(error) => Some(Err(self.reject(total, error))),
        }
    }

    /// Pushes `bytes` a frame's worth at a time and yields every frame and rejected candidate in
    /// order, never holding more than two frames' worth of bytes. When the iterator is dropped
    /// early, the bytes it did not reach are kept, beyond [`STREAM_CAPACITY`] if need be: drain
    /// them with [`Self::next_frame`] before the next push.
    pub fn feed<'a>(&'a mut self, bytes: &'a [u8], profile: &'a XbotProfile) -> Feed<'a> {
        Feed {
            parser: self,
            rest: bytes,
            profile,
        }
    }

    /// Bytes skipped so far: garbage, the rejected candidates' bytes and overflow.
    pub fn bytes_discarded(&self) -> u64 {
        self.bytes_discarded
    }

    /// Frames decoded so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Candidates rejected so far.
    pub fn errors(&self) -> u64 {
        self.errors
    }

    /// Bytes waiting for the rest of a frame.
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// Drops the waiting bytes (counted as discarded), e.g. after the port was reopened.
    pub fn clear(&mut self) {
        self.discard(self.pending());
        self.compact();
    }

    /// Consumes `n` waiting bytes as discarded.
    fn discard(&mut self, n: usize) {
        let n = n.min(self.pending());
        self.start += n;
        self.bytes_discarded += n as u64;
    }

    /// Forgets the consumed bytes.
    fn compact(&mut self) {
        self.buf.drain(..self.start);
        self.start = 0;
    }

    /// Discards everything before the first `AA 55` (or a final lone `AA`).
    fn skip_to_header(&mut self) {
        let data = &self.buf[self.start..];
        let skip = data
            .iter()
            .enumerate()
            .position(|(i, &b)| {
                b == HEADER[0] && data.get(i + 1).is_none_or(|&next| next == HEADER[1])
            })
            .unwrap_or(data.len());
        self.discard(skip);
    }

    /// Rejects the candidate at the start of the buffer: reports its first `examined` bytes and
    /// resumes scanning after its `AA`.
    fn reject(&mut self, examined: usize, error: DecodeError) -> StreamError {
        let data = &self.buf[self.start..];
        let raw = data[..examined.min(data.len())].to_vec();
        self.discard(1);
        self.errors += 1;
        StreamError { error, raw }
    }
}

/// Iterator of [`StreamParser::feed`].
#[derive(Debug)]
pub struct Feed<'a> {
    parser: &'a mut StreamParser,
    rest: &'a [u8],
    profile: &'a XbotProfile,
}

impl Iterator for Feed<'_> {
    type Item = Result<Frame, StreamError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(item) = self.parser.next_frame(self.profile) {
                return Some(item);
            }
            if self.rest.is_empty() {
                return None;
            }
            let (chunk, rest) = self.rest.split_at(self.rest.len().min(MAX_FRAME_LEN));
            self.parser.push(chunk);
            self.rest = rest;
        }
    }
}

impl Drop for Feed<'_> {
    fn drop(&mut self) {
        // Not `push`: its cap would drop the oldest of these bytes.
        self.parser.buf.extend_from_slice(self.rest);
    }
}
