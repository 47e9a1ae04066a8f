//! Any byte stream from a serial CAN adapter, in chunks chosen by the input, into the slcan line
//! parser: no panic, bounded memory, the same tokens in any chunking, every frame printed back
//! as slcan text reads as the same frame, and a frame line is taken exactly when it is strict
//! Lawicel text (an independent reading below decides).
#![no_main]

use chassis_protocols::CanFrame;
use chassis_protocols::slcan::{CR, LineParser, MAX_LINE, Token, decode_frame, encode_frame};
use libfuzzer_sys::fuzz_target;

fn tokens(stream: &[u8], chunk: usize) -> Vec<Token> {
    let mut parser = LineParser::default();
    let mut out = Vec::new();
    for piece in stream.chunks(chunk) {
        parser.push(piece, |t| out.push(t));
        assert!(parser.pending() <= MAX_LINE);
    }
    out
}

/// `tIIIL…` / `TIIIIIIIIL…`: hex digits only after the letter, a DLC of at most 8, exactly DLC
/// bytes, then nothing or a 4-digit timestamp; an id the frame type can hold.
fn lawicel(line: &[u8]) -> Option<CanFrame> {
    let (extended, id_len) = match line.first()? {
        b't' => (false, 3),
        b'T' => (true, 8),
        _ => return None,
    };
    let text = std::str::from_utf8(&line[1..]).ok()?;
    if !text.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    let id = u32::from_str_radix(text.get(..id_len)?, 16).ok()?;
    let dlc = usize::from_str_radix(text.get(id_len..id_len + 1)?, 16).ok()?;
    if dlc > 8 {
        return None;
    }
    let data_hex = text.get(id_len + 1..id_len + 1 + 2 * dlc)?;
    let timestamp = text.len() - (id_len + 1 + 2 * dlc);
    if timestamp != 0 && timestamp != 4 {
        return None;
    }
    let data = (0..dlc)
        .map(|i| u8::from_str_radix(&data_hex[2 * i..2 * i + 2], 16))
        .collect::<Result<Vec<u8>, _>>()
        .ok()?;
    if extended {
        CanFrame::new_extended(id, &data).ok()
    } else {
        CanFrame::new(id, &data).ok()
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&chunking, stream)) = data.split_first() else {
        return;
    };
    let whole = tokens(stream, stream.len().max(1));
    assert_eq!(tokens(stream, usize::from(chunking).max(1)), whole);
    for token in &whole {
        if let Token::Frame(frame) = token {
            let text = encode_frame(frame);
            assert_eq!(tokens(&text, text.len()), vec![Token::Frame(*frame)]);
        }
    }
    for line in stream.split(|&b| b == CR) {
        assert_eq!(
            decode_frame(line),
            lawicel(line),
            "{:?}",
            String::from_utf8_lossy(line)
        );
    }
});
