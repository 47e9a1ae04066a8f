//! Helpers the XBot's codec, driver, simulator and scenario tests share.

use std::time::Duration;

use chassis_interfaces::Velocity;
use proptest::prelude::*;

use crate::time::Timestamp;
use crate::xbot::XbotProfile;

pub(crate) fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

/// The manual's profile.
pub(crate) fn p() -> XbotProfile {
    XbotProfile::default()
}

pub(crate) fn twist(vx: f32, vy: f32, wz: f32) -> Velocity {
    Velocity::new(vx, vy, wz).unwrap()
}

/// `"AA 55 02 01 01 02"` → bytes.
pub(crate) fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

pub(crate) fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

/// The largest number of `times` inside any one-second window `[t, t + 1 s)`.
pub(crate) fn max_per_second(times: &[Timestamp]) -> usize {
    times
        .iter()
        .map(|&start| {
            times
                .iter()
                .filter(|&&t| t >= start && t < start + ms(1000))
                .count()
        })
        .max()
        .unwrap_or(0)
}

/// Up to 2000 arbitrary bytes as a UART returns them: in reads of 1-299 bytes ([`pieces`]).
pub(crate) fn arbitrary_reads() -> impl Strategy<Value = Vec<Vec<u8>>> {
    (
        proptest::collection::vec(any::<u8>(), 0..2000),
        proptest::collection::vec(1usize..300, 1..20),
    )
        .prop_map(|(data, cuts)| {
            pieces(&data, &cuts)
                .into_iter()
                .map(<[u8]>::to_vec)
                .collect()
        })
}

/// `data` cut into consecutive pieces of the lengths `cuts` gives, in turn (the last piece may
/// be shorter): a byte stream as a UART read may return it.
pub(crate) fn pieces<'a>(data: &'a [u8], cuts: &[usize]) -> Vec<&'a [u8]> {
    let mut out = Vec::new();
    let mut rest = data;
    let mut cut = cuts.iter().cycle();
    while !rest.is_empty() {
        let n = cut.next().map_or(rest.len(), |&n| n.clamp(1, rest.len()));
        out.push(&rest[..n]);
        rest = &rest[n..];
    }
    out
}
