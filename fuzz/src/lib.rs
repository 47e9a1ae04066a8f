//! What the fuzz targets share: how raw fuzzer input becomes the frames the decoders take.

use chassis_protocols::CanFrame;

/// A standard-id CAN frame from fuzzer input: two bytes of id (little-endian, kept to its 11
/// bits), then up to 8 data bytes (more are cut off); `None` when the input is shorter than the
/// id.
pub fn standard_frame(data: &[u8]) -> Option<CanFrame> {
    let (head, payload) = data.split_first_chunk::<2>()?;
    let id = u32::from(u16::from_le_bytes(*head)) & CanFrame::MAX_STANDARD_ID;
    CanFrame::new(id, &payload[..payload.len().min(8)]).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_two_bytes_are_the_id_and_at_most_eight_follow() {
        let frame = standard_frame(&[0x21, 0xF2, 1, 2, 3, 4, 5, 6, 7, 8, 9]).unwrap();
        assert_eq!((frame.id(), frame.data()), (0x221, &[1, 2, 3, 4, 5, 6, 7, 8][..]));
        assert_eq!(standard_frame(&[0x21]), None);
    }
}
