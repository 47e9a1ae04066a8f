//! Fixed-length, NUL-padded UTF-8 text inside fixed-layout samples.

/// Writes `text` into `buf`, NUL-padded. Text longer than the buffer is cut at the last UTF-8
/// character boundary that fits, so the stored bytes are always valid UTF-8.
pub fn write_fixed_str(buf: &mut [u8], text: &str) {
    let mut end = text.len().min(buf.len());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    buf.fill(0);
    buf[..end].copy_from_slice(&text.as_bytes()[..end]);
}

/// Reads NUL-padded UTF-8 text. Bytes after the first NUL are ignored; invalid UTF-8 (which only
/// a foreign writer can produce) is cut at the first invalid byte.
pub fn read_fixed_str(buf: &[u8]) -> &str {
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    match core::str::from_utf8(&buf[..end]) {
        Ok(text) => text,
        Err(err) => core::str::from_utf8(&buf[..err.valid_up_to()]).unwrap_or(""),
    }
}

/// `serde` helper: serializes a fixed text buffer as a string.
pub(crate) fn serialize_fixed_str<S: serde::Serializer>(
    buf: &[u8],
    serializer: S,
) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(read_fixed_str(buf))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_text_round_trips_and_pads_with_nul() {
        let mut buf = [0xffu8; 8];
        write_fixed_str(&mut buf, "teleop");
        assert_eq!(&buf, b"teleop\0\0");
        assert_eq!(read_fixed_str(&buf), "teleop");
    }

    #[test]
    fn fixed_text_is_cut_on_a_character_boundary() {
        let mut buf = [0u8; 4];
        write_fixed_str(&mut buf, "abcé"); // 'é' is two bytes and does not fit
        assert_eq!(read_fixed_str(&buf), "abc");
    }

    #[test]
    fn fixed_text_stops_at_invalid_utf8() {
        assert_eq!(read_fixed_str(&[b'o', b'k', 0xff, b'x']), "ok");
    }
}
