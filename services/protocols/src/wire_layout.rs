//! Helpers shared by the codecs: reading a zerocopy wire layout out of a frame's bytes.

use zerocopy::{FromBytes, Immutable, KnownLayout};

use crate::DecodeError;

/// Reads wire layout `W` from the start of `data`. Extra bytes are ignored (some firmware pads
/// every frame to 8 bytes); too few is [`DecodeError::TooShort`].
pub(crate) fn read_prefix<W: FromBytes + KnownLayout + Immutable>(
    id: u32,
    data: &[u8],
) -> Result<W, DecodeError> {
    W::read_from_prefix(data)
        .map(|(wire, _rest)| wire)
        .map_err(|_| DecodeError::TooShort {
            id,
            len: data.len(),
            need: size_of::<W>(),
        })
}

/// A boolean command byte: 0x00 or 0x01, anything else is undefined.
pub(crate) fn read_bool(id: u32, field: &'static str, byte: u8) -> Result<bool, DecodeError> {
    match byte {
        0x00 => Ok(false),
        0x01 => Ok(true),
        value => Err(invalid(id, field, value)),
    }
}

/// The first data byte of frame `id` (one-byte commands); none is [`DecodeError::TooShort`].
pub(crate) fn first_byte(id: u32, data: &[u8]) -> Result<u8, DecodeError> {
    read_prefix(id, data)
}

/// [`DecodeError::InvalidValue`] for a field of frame `id`.
pub(crate) fn invalid(id: u32, field: &'static str, value: impl Into<u32>) -> DecodeError {
    DecodeError::InvalidValue {
        id,
        field,
        value: value.into(),
    }
}

/// The number, from 1, of `id` in a block of `count` consecutive ids starting at `first` (motor
/// 1-n, sensor 1-n); `None` outside it.
pub(crate) fn index_in(id: u16, first: u16, count: u16) -> Option<u8> {
    (first..first.saturating_add(count))
        .contains(&id)
        .then(|| u8::try_from(id - first + 1).ok())
        .flatten()
}

/// Decodes `raw / scale` for display and state (`scale` = wire units per SI unit).
pub(crate) fn si(raw: impl Into<f64>, scale: f64) -> f64 {
    raw.into() / scale
}

/// `f` of each of `values`, in order, or the first error: a wire array field converted element by
/// element.
pub(crate) fn try_map<A, B: Default, E, const N: usize>(
    values: [A; N],
    mut f: impl FnMut(A) -> Result<B, E>,
) -> Result<[B; N], E> {
    let mut out: [B; N] = std::array::from_fn(|_| B::default());
    for (slot, value) in out.iter_mut().zip(values) {
        *slot = f(value)?;
    }
    Ok(out)
}

/// The bytes of a wire layout as an array of its documented length (`N` = the frame's DLC).
/// A layout shorter than `N` is zero-padded; the layout tests pin every size to its DLC.
pub(crate) fn wire_bytes<const N: usize, W: zerocopy::IntoBytes + Immutable>(wire: W) -> [u8; N] {
    let mut out = [0u8; N];
    let bytes = wire.as_bytes();
    let n = bytes.len().min(N);
    out[..n].copy_from_slice(&bytes[..n]);
    out
}
