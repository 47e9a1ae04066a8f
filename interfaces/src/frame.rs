//! `BusFrame`: a tap of every frame on the bus, both directions.

use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

use crate::layout::ipc_type;
use crate::named::named_constants;

named_constants! {
    /// [`BusFrame::direction`].
    pub enum FrameDirection: u8 {
        /// Received from the chassis.
        RX = 0 => "rx",
        /// Sent to the chassis.
        TX = 1 => "tx",
    }
}

named_constants! {
    /// [`BusFrame::kind`].
    pub enum FrameKind: u8 {
        /// A CAN frame: `can_id` and up to 8 data bytes.
        CAN = 0 => "can",
        /// A chunk of the serial byte stream (XBot), as read or written.
        SERIAL = 1 => "serial",
        /// A chunk of the GPS receiver's NMEA stream.
        GPS = 2 => "gps",
    }
}

ipc_type! {
    /// One CAN frame or one chunk of a serial stream.
    #[derive(Serialize)]
    #[type_name("chassis::BusFrame.v1")]
    pub struct BusFrame {
        /// `CLOCK_MONOTONIC` time the frame was read from or written to the bus, ns.
        pub stamp_ns: u64,
        /// Incremented for every frame published on the tap (gaps mean the tap dropped frames).
        pub seq: u64,
        /// CAN identifier (11-bit standard or 29-bit extended); 0 for serial chunks.
        pub can_id: u32,
        /// [`FrameDirection`].
        pub direction: u8,
        /// [`FrameKind`].
        pub kind: u8,
        /// Number of valid bytes in `data`.
        pub len: u8,
        /// [`BusFrame::EXTENDED_ID`], [`BusFrame::REMOTE`].
        pub flags: u8,
        #[serde(skip)]
        pub data: [u8; BusFrame::DATA_LEN],
    }
}

impl Default for BusFrame {
    fn default() -> Self {
        Self {
            direction: FrameDirection::RX,
            kind: FrameKind::CAN,
            ..zerocopy::FromZeros::new_zeroed()
        }
    }
}

impl BusFrame {
    /// Room for a whole XBot sensor frame (75 bytes) in one chunk.
    pub const DATA_LEN: usize = 80;
    pub const EXTENDED_ID: u8 = 1 << 0;
    pub const REMOTE: u8 = 1 << 1;

    /// The valid bytes.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len).min(Self::DATA_LEN)]
    }

    /// Copies `bytes` into `data` (at most [`BusFrame::DATA_LEN`]; returns how many were taken).
    pub fn set_payload(&mut self, bytes: &[u8]) -> usize {
        let n = bytes.len().min(Self::DATA_LEN);
        self.data[..n].copy_from_slice(&bytes[..n]);
        self.data[n..].fill(0);
        // n <= DATA_LEN (80) always fits a u8.
        self.len = n as u8;
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payload_is_cut_to_the_buffer() {
        let mut frame = BusFrame::default();
        assert_eq!(frame.set_payload(&[7u8; 100]), BusFrame::DATA_LEN);
        assert_eq!(frame.payload().len(), BusFrame::DATA_LEN);
        frame.set_payload(&[1, 2, 3]);
        assert_eq!(frame.payload(), &[1, 2, 3]);
    }
}
