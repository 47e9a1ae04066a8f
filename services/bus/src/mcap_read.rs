//! MCAP files read record by record without the panics mcap 0.26 has on some corrupt files: the
//! replay bus reads `chassis record`'s files with it, and chassisd's black box its kept windows.

use std::ops::ControlFlow;

use mcap::McapError;

/// The longest record read: the recordings' records are a message each (or a chunk of about
/// 1 MiB, mcap's default), far shorter than that.
const RECORD_CEILING: usize = 64 << 20;

/// Hands every record of an MCAP file to `each`, in order, a chunk's records in its place, until
/// `each` breaks: its opcode and its bytes, unparsed — parse only the kinds needed
/// (`mcap::parse_record`), as mcap 0.26 panics on some corrupt records of other kinds (a short
/// attachment). A corrupt file is an error, never a panic: a record longer than 64 MiB is refused
/// before mcap reserves it, and an uncompressed chunk whose record runs past the chunk's end is
/// `McapError::UnexpectedEoc` before mcap reads it (mcap 0.26 overflows on it).
pub fn each_record<E: From<McapError>>(
    bytes: &[u8],
    mut each: impl FnMut(u8, &[u8]) -> Result<ControlFlow<()>, E>,
) -> Result<(), E> {
    uncompressed_chunks_fit(bytes)?;
    let options =
        mcap::sans_io::LinearReaderOptions::default().with_record_length_limit(RECORD_CEILING);
    let mut reader = mcap::sans_io::LinearReader::new_with_options(options);
    let mut input = bytes;
    while let Some(event) = reader.next_event() {
        match event? {
            mcap::sans_io::LinearReadEvent::ReadRequest(need) => {
                let (now, later) = input.split_at(need.min(input.len()));
                reader.insert(now.len()).copy_from_slice(now);
                reader.notify_read(now.len());
                input = later;
            }
            mcap::sans_io::LinearReadEvent::Record { opcode, data } => {
                if each(opcode, data)?.is_break() {
                    break;
                }
            }
        }
    }
    Ok(())
}

/// Refuses an uncompressed chunk whose records claim more bytes than the chunk holds: mcap 0.26
/// reads such a chunk into an arithmetic overflow (a panic) instead of an error. The file's
/// top-level records are walked by their lengths; whatever else is wrong is left to mcap to say.
fn uncompressed_chunks_fit(bytes: &[u8]) -> Result<(), McapError> {
    const CHUNK: u8 = 0x06;
    let word = |at: u64, offset: u64| -> Option<u64> {
        let at = usize::try_from(at.checked_add(offset)?).ok()?;
        Some(u64::from_le_bytes(*bytes.get(at..)?.first_chunk::<8>()?))
    };
    // Records by their lengths (opcode: 1 byte, length: u64, then the record), in u64 so that no
    // length a file claims overflows; a file may end inside a record (mcap reports that).
    let mut at = mcap::MAGIC.len() as u64;
    while let Some(len) = word(at, 1) {
        let body = at + 9;
        // A chunk: start and end times, uncompressed size (u64 each), uncompressed CRC (u32),
        // compression (a u32-long name, empty when uncompressed), records (a u64-long array).
        if bytes.get(at as usize) == Some(&CHUNK)
            && word(body, 28).is_some_and(|w| w as u32 == 0)
            && let Some(records_len) = word(body, 32)
        {
            let mut record = body + 40;
            let end = record.checked_add(records_len);
            while let Some(len) = end
                .filter(|&end| record < end)
                .and_then(|_| word(record, 1))
            {
                record = (record + 9)
                    .checked_add(len)
                    .filter(|&next| Some(next) <= end)
                    .ok_or(McapError::UnexpectedEoc)?;
            }
            if end.is_none() {
                return Err(McapError::UnexpectedEoc);
            }
        }
        let Some(next) = body.checked_add(len) else {
            break;
        };
        at = next;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An MCAP file of one uncompressed chunk whose one record claims `claimed` bytes, that many
    /// zeros after it (what mcap 0.26 reads the record from).
    fn one_chunk(claimed: u64) -> Vec<u8> {
        let mut records = vec![0x05];
        records.extend(claimed.to_le_bytes());
        let mut chunk = vec![0u8; 28]; // start, end, uncompressed size, CRC
        chunk.extend(0u32.to_le_bytes()); // no compression
        chunk.extend((records.len() as u64).to_le_bytes());
        chunk.extend(&records);
        let mut file = mcap::MAGIC.to_vec();
        file.push(0x06);
        file.extend((chunk.len() as u64).to_le_bytes());
        file.extend(chunk);
        file.extend(vec![0; claimed as usize]);
        file
    }

    #[test]
    fn a_chunk_record_longer_than_its_chunk_is_an_error_not_mcaps_panic() {
        let walked =
            each_record::<McapError>(&one_chunk(100), |_, _| Ok(ControlFlow::Continue(())));
        assert!(
            matches!(walked, Err(McapError::UnexpectedEoc)),
            "{walked:?}"
        );
        // A record that fits is mcap's to read (here: a file without its end).
        let walked = each_record::<McapError>(&one_chunk(0), |_, _| Ok(ControlFlow::Continue(())));
        assert!(
            !matches!(walked, Err(McapError::UnexpectedEoc)),
            "{walked:?}"
        );
    }
}
