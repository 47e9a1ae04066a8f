//! Cutting the GPS receiver's byte stream into sentences.

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Longest line kept by default, `$` included, CR LF excluded. NMEA allows 82 characters; the
/// XBot manual lists GSV frames of up to 210.
pub const DEFAULT_MAX_LINE_LEN: usize = 256;

/// Most complete lines a [`LineReader`] queues before it drops the oldest.
pub const MAX_QUEUED_LINES: usize = 1024;

/// Incremental line splitter for an NMEA stream.
///
/// A line starts at `$` and ends at CR or LF (so CR LF, LF and CR all work). Bytes outside a
/// line are discarded and counted; a `$` inside a line starts a new one (the interrupted line is
/// dropped); a line longer than the limit, or holding a byte that is not printable ASCII, is
/// dropped and counted. Lines come out without their terminator; whether they are valid
/// sentences is [`super::parse_sentence`]'s business. Memory is bounded: one partial line and
/// at most [`MAX_QUEUED_LINES`] complete ones.
#[derive(Debug, Serialize, Deserialize)]
pub struct LineReader {
    max_len: usize,
    /// The line being received, from its `$`; empty outside a line.
    current: Vec<u8>,
    /// Inside an overlong line: skip to its end.
    skipping: bool,
    ready: VecDeque<String>,
    lines_dropped: u64,
    bytes_discarded: u64,
}

impl Default for LineReader {
    fn default() -> Self {
        Self::new()
    }
}

impl LineReader {
    pub fn new() -> Self {
        Self::with_max_len(DEFAULT_MAX_LINE_LEN)
    }

    /// A reader that drops lines longer than `max_len` bytes (`$` included, at least 1).
    pub fn with_max_len(max_len: usize) -> Self {
        Self {
            max_len: max_len.max(1),
            current: Vec::new(),
            skipping: false,
            ready: VecDeque::new(),
            lines_dropped: 0,
            bytes_discarded: 0,
        }
    }

    /// Takes received bytes; complete lines become available from [`Self::next_line`].
    pub fn push(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match b {
                b'$' => {
                    if !self.current.is_empty() {
                        // A new sentence began before the last one ended.
                        self.lines_dropped += 1;
                    }
                    self.current.clear();
                    self.current.push(b);
                    self.skipping = false;
                }
                b'\r' | b'\n' => {
                    if !self.current.is_empty() {
                        self.finish_line();
                    }
                    self.skipping = false;
                }
                _ if self.skipping => {}
                _ if self.current.is_empty() => self.bytes_discarded += 1,
                _ if self.current.len() >= self.max_len => {
                    self.lines_dropped += 1;
                    self.current.clear();
                    self.skipping = true;
                }
                _ => self.current.push(b),
            }
        }
    }

    /// The next complete line, oldest first.
    pub fn next_line(&mut self) -> Option<String> {
        self.ready.pop_front()
    }

    /// Lines dropped so far: too long, not printable ASCII, interrupted by a `$`, or pushed
    /// out of a full queue.
    pub fn lines_dropped(&self) -> u64 {
        self.lines_dropped
    }

    /// Bytes outside any line (CR and LF not counted).
    pub fn bytes_discarded(&self) -> u64 {
        self.bytes_discarded
    }

    fn finish_line(&mut self) {
        let line = std::mem::take(&mut self.current);
        if !line.iter().all(|b| (0x20..=0x7E).contains(b)) {
            self.lines_dropped += 1;
            return;
        }
        match String::from_utf8(line) {
            Ok(text) => {
                if self.ready.len() >= MAX_QUEUED_LINES {
                    self.ready.pop_front();
                    self.lines_dropped += 1;
                }
                self.ready.push_back(text);
            }
            // Unreachable: printable ASCII is UTF-8.
            Err(_) => self.lines_dropped += 1,
        }
    }
}
