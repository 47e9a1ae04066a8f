//! Any CAN frame into the SCOUT MINI decoder: no panic; a frame that decodes has a valid
//! checksum and round-trips with its count.
#![no_main]

use chassis_protocols::profile::ScoutMiniProfile;
use chassis_protocols::scout_mini;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some(frame) = chassis_fuzz::standard_frame(data) else {
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
