//! Any CAN frame into the TITAN decoder (both profile sign choices): no panic, and whatever
//! decodes re-encodes and decodes to the same frame.
#![no_main]

use chassis_protocols::titan::TitanProfile;
use chassis_protocols::titan;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some(frame) = chassis_fuzz::standard_frame(data) else {
        return;
    };
    for left_positive in [false, true] {
        let profile = TitanProfile {
            steering_feedback_left_positive: left_positive,
            ..TitanProfile::default()
        };
        if let Ok(decoded) = titan::decode(&frame, &profile) {
            let encoded = decoded.encode(&profile).expect("a decoded frame encodes");
            assert_eq!(titan::decode(&encoded, &profile).expect("re-decodes"), decoded);
        }
    }
});
