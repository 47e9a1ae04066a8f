//! Any CAN frame into the AgileX protocol-V2 decoder, under every model's profile and the
//! doubtful (⚠) choices the input picks: no panic; whatever decodes has the frame's id,
//! encodes, and decodes again to the same frame.
#![no_main]

use chassis_protocols::agilex_v2::profile::{BmsAlarmLayout, RcStickOrder};
use chassis_protocols::agilex_v2::{self, V2Model, V2Profile};
use libfuzzer_sys::fuzz_target;

const MODELS: &[V2Model] = &V2Model::ALL;

/// Low nibble: the model; high bits flip one doubtful choice each.
fn profile(choice: u8) -> V2Profile {
    let mut p = V2Profile::for_model(MODELS[usize::from(choice & 0x0F) % MODELS.len()]);
    if choice & 0x10 != 0 {
        p.bms_alarm_layout = match p.bms_alarm_layout {
            BmsAlarmLayout::AlarmWarning => BmsAlarmLayout::ProtectionCodes,
            BmsAlarmLayout::ProtectionCodes => BmsAlarmLayout::AlarmWarning,
        };
    }
    if choice & 0x20 != 0 {
        p.rc_stick_order = match p.rc_stick_order {
            RcStickOrder::Sdk => RcStickOrder::Pya,
            RcStickOrder::Pya => RcStickOrder::Sdk,
        };
    }
    if choice & 0x40 != 0 {
        p.short_commands_dlc = if p.short_commands_dlc == 1 { 8 } else { 1 };
    }
    if choice & 0x80 != 0 {
        p.lateral_left_positive = !p.lateral_left_positive;
    }
    p
}

fuzz_target!(|data: &[u8]| {
    let Some((&choice, rest)) = data.split_first() else {
        return;
    };
    let Some(frame) = chassis_fuzz::standard_frame(rest) else {
        return;
    };
    let profile = profile(choice);
    if let Ok(decoded) = agilex_v2::decode(&frame, &profile) {
        assert_eq!(u32::from(decoded.id()), frame.id(), "{decoded:?}");
        let encoded = decoded
            .encode(&profile)
            .unwrap_or_else(|e| panic!("{decoded:?} decoded from {frame:?} does not encode: {e}"));
        assert_eq!(
            agilex_v2::decode(&encoded, &profile).expect("an encoded frame decodes"),
            decoded
        );
    }
});
