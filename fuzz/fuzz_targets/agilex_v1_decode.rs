//! Any CAN frame into the SCOUT MINI decoder: no panic; a frame that decodes has a valid
//! checksum and round-trips with its count.
#![no_main]

use chassis_protocols::agilex_v1::V1Profile;
use chassis_protocols::agilex_v1;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some(frame) = chassis_fuzz::standard_frame(data) else {
        return;
    };
    let profile = V1Profile::default();
    if let Ok(decoded) = agilex_v1::decode(&frame, &profile) {
        let encoded = decoded
            .frame
            .encode(decoded.count, &profile)
            .expect("a decoded frame encodes");
        assert_eq!(agilex_v1::decode(&encoded, &profile).expect("re-decodes"), decoded);
    }
});
