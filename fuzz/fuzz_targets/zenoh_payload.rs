//! Any payload, under any media type, into the decoder chassis-zenoh applies to what another
//! computer sends (`chassis_interfaces::payload`), for every type it carries: no panic; taken
//! exactly when the media type names the type, the length is a whole number of values and no
//! robot description counts more sensors, joints or sources than its lists hold; a velocity
//! request taken is parsed into a `ValidRequest` exactly when it carries no NaN, no infinity
//! and no negative envelope (both judged here from the contract's layout, not from the code's
//! own checks); what is taken is the bytes that came, and reads back (names, JSON, control
//! requests as chassisd reads them) without a panic.
#![no_main]

use chassis_interfaces::layout::{FieldType, Layout};
use chassis_interfaces::payload::{Payload, PayloadError, PayloadType};
use chassis_interfaces::{
    BusFrame, ChassisState, ControlRequest, ControlResponse, MuxStatus, RequestFlags,
    RobotDescription, ValidRequest, VelocityRequest,
};
use chassis_protocols::{ControlAction, command_to_request, request_to_action};
use libfuzzer_sys::fuzz_target;
use zerocopy::IntoBytes;

const MEDIA_TYPES: usize = 7;

fn media_type(index: usize) -> String {
    match index % MEDIA_TYPES {
        0 => PayloadType::<VelocityRequest>::new().media_type().to_string(),
        1 => PayloadType::<ControlRequest>::new().media_type().to_string(),
        2 => PayloadType::<ChassisState>::new().media_type().to_string(),
        3 => PayloadType::<MuxStatus>::new().media_type().to_string(),
        4 => PayloadType::<BusFrame>::new().media_type().to_string(),
        5 => PayloadType::<ControlResponse>::new().media_type().to_string(),
        _ => PayloadType::<RobotDescription>::new().media_type().to_string(),
    }
}

/// A robot description the operator's computer must not take: a count (`sensor_count`, …)
/// beyond the length of the list it counts (`sensors`, …), both read from the contract.
fn must_refuse_description(chunk: &[u8]) -> bool {
    let layout = RobotDescription::layout();
    let field = |name: &str| layout.fields.iter().find(|f| f.name == name).expect("a field");
    [("sensor_count", "sensors"), ("joint_count", "joints"), ("source_count", "sources")]
        .iter()
        .any(|(count, list)| {
            let len = match &field(list).ty {
                FieldType::Array { len, .. } => *len,
                other => panic!("{list} is {other:?}, not a list"),
            };
            usize::from(chunk[field(count).offset]) > len
        })
}

/// A velocity request the robot must not take: a non-finite `f32` anywhere (every `f32` field
/// the contract lists), or a negative bound of a limit.
fn must_refuse_velocity(chunk: &[u8]) -> bool {
    let layout = VelocityRequest::layout();
    let f32_at = |name: &str| {
        let field = layout.fields.iter().find(|f| f.name == name).expect("a field");
        let bytes: [u8; 4] = chunk[field.offset..field.offset + 4].try_into().expect("4 bytes");
        f32::from_ne_bytes(bytes)
    };
    let non_finite = layout.fields.iter().any(|f| {
        f.ty == (FieldType::Primitive { primitive: "f32" }) && !f32_at(f.name).is_finite()
    });
    let flags_field = layout.fields.iter().find(|f| f.name == "flags").expect("flags");
    let flags = u32::from_ne_bytes(
        chunk[flags_field.offset..flags_field.offset + 4].try_into().expect("4 bytes"),
    );
    let negative_limit = flags & RequestFlags::LIMIT != 0
        && [
            "limit_forward_mps",
            "limit_reverse_mps",
            "limit_lateral_mps",
            "limit_angular_radps",
        ]
        .iter()
        .any(|name| f32_at(name) < 0.0);
    // A standing speed limit is more than 0 m/s.
    let no_speed_limit = flags & RequestFlags::SPEED_LIMIT != 0 && f32_at("speed_limit_mps") <= 0.0;
    non_finite || negative_limit || no_speed_limit
}

/// Decodes `bytes` as `T` and checks the outcome against a model of the rules; `read` reads
/// every taken value the way the bridges and chassisd do.
fn check<T: Payload>(
    media: &str,
    bytes: &[u8],
    refuse: impl Fn(&[u8]) -> bool,
    read: impl Fn(&T),
) {
    let payloads = PayloadType::<T>::new();
    let size = size_of::<T>();
    let result = payloads.decode_all(media, bytes);
    if media != payloads.media_type() {
        assert!(matches!(result, Err(PayloadError::MediaType { .. })), "{result:?}");
        return;
    }
    if bytes.len() % size != 0 {
        assert!(matches!(result, Err(PayloadError::Size { .. })), "{result:?}");
        return;
    }
    let refused = bytes.chunks_exact(size).position(&refuse);
    match (refused, &result) {
        (Some(index), Err(PayloadError::Refused { index: got, .. })) => assert_eq!(index, *got),
        (None, Ok(values)) => {
            assert_eq!(values.as_slice().as_bytes(), bytes);
            values.iter().for_each(&read);
            let one = payloads.decode(media, bytes);
            assert_eq!(one.is_ok(), values.len() == 1, "{one:?}");
        }
        (expected, got) => panic!("refused {expected:?}, decoded {got:?}"),
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&choice, rest)) = data.split_first() else {
        return;
    };
    // Bit 7: another type's media type; bit 6: the input's own text up to a NUL.
    let (media, bytes) = if choice & 0x40 != 0 {
        let end = rest.iter().position(|&b| b == 0).unwrap_or(rest.len());
        (
            String::from_utf8_lossy(&rest[..end]).into_owned(),
            rest.get(end + 1..).unwrap_or_default(),
        )
    } else if choice & 0x80 != 0 {
        (media_type(usize::from(choice >> 3)), rest)
    } else {
        (media_type(usize::from(choice)), rest)
    };
    match usize::from(choice & 0x07) % MEDIA_TYPES {
        0 => check::<VelocityRequest>(&media, bytes, |_| false, |r| {
            let refused = ValidRequest::try_from(*r).is_err();
            assert_eq!(refused, must_refuse_velocity(r.as_bytes()), "{r:?}");
        }),
        1 => check::<ControlRequest>(&media, bytes, |_| false, |r| {
            let _ = r.name();
            // The robot side hands it to chassisd, which reads it so: what it takes as a
            // chassis command asks for the same thing once written back.
            if let Ok(ControlAction::Chassis(command)) = request_to_action(r) {
                let again = command_to_request(&command).expect("a chassis command");
                assert_eq!(
                    request_to_action(&again),
                    Ok(ControlAction::Chassis(command))
                );
            }
        }),
        2 => check::<ChassisState>(&media, bytes, |_| false, |s| {
            serde_json::to_vec(s).expect("a state prints as JSON");
        }),
        3 => check::<MuxStatus>(&media, bytes, |_| false, |m| {
            for source in m.sources() {
                let _ = source.name();
            }
            for lock in m.locks() {
                let _ = lock.name();
            }
            let _ = m.active();
            serde_json::to_vec(m).expect("a mux decision prints as JSON");
        }),
        4 => check::<BusFrame>(&media, bytes, |_| false, |f| {
            assert!(f.payload().len() <= BusFrame::DATA_LEN);
        }),
        5 => check::<ControlResponse>(&media, bytes, |_| false, |r| {
            let _ = r.message();
            let _ = r.is_ok();
        }),
        // The mirror republishes it to the operator's clients, which read its lists and names.
        _ => check::<RobotDescription>(&media, bytes, must_refuse_description, |d| {
            assert!(d.sensors().len() == usize::from(d.sensor_count));
            assert!(d.joints().len() == usize::from(d.joint_count));
            assert!(d.sources().len() == usize::from(d.source_count));
            let _ = (d.name(), d.model(), d.kind_name(), d.display_name());
            let names = d.sensors().iter().map(|s| s.name().len()).sum::<usize>()
                + d.joints().iter().map(|j| j.name().len()).sum::<usize>()
                + d.sources().iter().map(|s| s.name().len()).sum::<usize>();
            assert!(names <= 32 * (d.sensors().len() + d.joints().len() + d.sources().len()));
        }),
    }
});
