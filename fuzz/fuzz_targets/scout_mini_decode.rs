//! Any CAN frame into the SCOUT MINI decoder: no panic; a frame that decodes has a valid
//! checksum and round-trips with its count.
#![no_main]

use chassis_protocols::profile::ScoutMiniProfile;
use chassis_protocols::{CanFrame, scout_mini};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((head, payload)) = data.split_first_chunk::<2>() else {
        return;
    };
    let id = u32::from(u16::from_le_bytes(*head)) & 0x7FF;
    let Ok(frame) = CanFrame::new(id, &payload[..payload.len().min(8)]) else {
        return;
    };
    let profile = ScoutMiniProfile::default();
    if let Ok(decoded) = scout_mini::decode(&frame, &profile) {
        let encoded = decoded
            .frame
            .encode(decoded.count, &profile)
            .expect("a decoded frame encodes");
        assert_eq!(scout_mini::decode(&encoded, &profile).expect("re-decodes"), decoded);
    }
});
