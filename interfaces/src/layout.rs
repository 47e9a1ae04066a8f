//! Machine-readable descriptions of every IPC type and of its constant groups.
//!
//! Programs in other languages (Python `ctypes` mirrors, ROS 2, Foxglove and Zenoh bridges) read
//! the layouts from here instead of from the Rust source. Each `#[repr(C)]` type is declared
//! through `ipc_type!`, which describes it from its own field list: offsets come from
//! `core::mem::offset_of!` and each field's type and size from the Rust field itself — and a test
//! checks that the fields of every type cover every byte, in order (the types have no padding:
//! zerocopy's `IntoBytes` proves it).

use serde::Serialize;

/// The type of one field.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FieldType {
    /// `u8` … `u64`, `i8` … `i64`, `f32`, `f64`.
    Primitive { primitive: &'static str },
    /// A fixed-length array of `len` elements of `element`.
    Array { element: Box<FieldType>, len: usize },
    /// A described struct, by its Rust name (a key of the contract's types).
    Struct {
        #[serde(rename = "struct")]
        name: &'static str,
    },
}

impl FieldType {
    /// The Rust spelling: `u64`, `[f32; 4]`, `MotionState`.
    pub fn rust(&self) -> String {
        match self {
            FieldType::Primitive { primitive } => (*primitive).to_string(),
            FieldType::Array { element, len } => format!("[{}; {len}]", element.rust()),
            FieldType::Struct { name } => (*name).to_string(),
        }
    }
}

/// Types that may appear as a field of a described type.
pub trait FieldKind {
    fn field_type() -> FieldType;
}

macro_rules! primitive {
    ($($t:ty),+) => {
        $(impl FieldKind for $t {
            fn field_type() -> FieldType {
                FieldType::Primitive { primitive: stringify!($t) }
            }
        })+
    };
}
primitive!(u8, u16, u32, u64, i8, i16, i32, i64, f32, f64);

impl<T: FieldKind, const N: usize> FieldKind for [T; N] {
    fn field_type() -> FieldType {
        FieldType::Array {
            element: Box::new(T::field_type()),
            len: N,
        }
    }
}

/// One field of a described type.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Field {
    pub name: &'static str,
    /// Bytes from the start of the type.
    pub offset: usize,
    pub size: usize,
    #[serde(rename = "type")]
    pub ty: FieldType,
    /// NUL-padded UTF-8 text in a byte array (declared `as text` in `ipc_type!`): mirrors in
    /// other languages read it as a string. Left out of the contract when false.
    #[serde(skip_serializing_if = "core::ops::Not::not")]
    pub text: bool,
}

impl Field {
    /// The field `name` at `offset`, of the type `select` returns (a closure naming the field:
    /// its type and size come from the struct itself).
    pub fn of<S, T: FieldKind>(name: &'static str, offset: usize, _select: fn(&S) -> &T) -> Self {
        Self {
            name,
            offset,
            size: core::mem::size_of::<T>(),
            ty: T::field_type(),
            text: false,
        }
    }

    /// This field, marked as text.
    pub fn text(self) -> Self {
        Self { text: true, ..self }
    }
}

/// A described type: its Rust name, iceoryx2 type name, size, alignment and fields.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TypeLayout {
    /// The Rust name (`ChassisState`): how fields and services refer to it.
    #[serde(skip)]
    pub name: &'static str,
    /// The iceoryx2 type name, with its layout version (`chassis::ChassisState.v4`).
    pub type_name: &'static str,
    pub size: usize,
    pub align: usize,
    /// Every field, in memory order.
    pub fields: Vec<Field>,
}

impl TypeLayout {
    /// Why the fields do not cover the type exactly once, in order (`None`: they do).
    pub fn gap(&self) -> Option<String> {
        let mut end = 0;
        for field in &self.fields {
            if field.offset != end {
                return Some(format!(
                    "{}: field {} starts at byte {} but the previous one ends at {end}",
                    self.name, field.name, field.offset
                ));
            }
            end = field.offset + field.size;
        }
        (end != self.size).then(|| {
            format!(
                "{}: the described fields end at byte {end}, the type is {} bytes long",
                self.name, self.size
            )
        })
    }
}

/// A `#[repr(C)]` IPC type described field by field (implemented by the crate's `ipc_type!`).
pub trait Layout: FieldKind {
    /// The Rust name, e.g. `ChassisState`.
    const NAME: &'static str;
    fn layout() -> TypeLayout;
}

/// Declares an IPC type and describes it from the same field list, so that no field can be
/// left out of the contract or listed out of order.
///
/// The struct gets what every IPC type has: `#[repr(C)]`, `Debug, Clone, Copy, PartialEq`,
/// zerocopy's `FromBytes, IntoBytes, Immutable, KnownLayout` (no padding, any bytes valid) and
/// iceoryx2's `ZeroCopySend`, whose `#[type_name("chassis::Name.vN")]` the declaration gives;
/// other derives (`Default`, `Serialize`) come with it. Its [`Layout`] lists every field, in
/// order, with `core::mem::offset_of!`. A byte array that holds NUL-padded UTF-8 text is declared
/// `pub name: [u8; NAME_LEN] as text`, so that the contract says so, and gets a getter of the
/// field's name that reads the text.
///
/// ```text
/// ipc_type! {
///     /// Pan and tilt servos (XBot), as commanded.
///     #[derive(Default, Serialize)]
///     #[type_name("chassis::PanTiltState.v1")]
///     pub struct PanTiltState {
///         /// Pan, rad: 0 ahead, left positive.
///         pub pan_rad: f32,
///         pub tilt_rad: f32,
///     }
/// }
/// ```
macro_rules! ipc_type {
    (@text $field:ident) => {
        pub fn $field(&self) -> &str {
            $crate::text::read_fixed_str(&self.$field)
        }
    };
    (
        $(#[$meta:meta])*
        pub struct $ty:ident {
            $(
                $(#[$field_meta:meta])*
                $vis:vis $field:ident : $field_ty:ty $(as $marker:ident)?
            ),+ $(,)?
        }
    ) => {
        #[repr(C)]
        #[derive(Debug, Clone, Copy, PartialEq, ::zerocopy::FromBytes, ::zerocopy::IntoBytes)]
        #[derive(::zerocopy::Immutable, ::zerocopy::KnownLayout)]
        #[derive(::iceoryx2_bb_derive_macros::ZeroCopySend)]
        $(#[$meta])*
        pub struct $ty {
            $($(#[$field_meta])* $vis $field: $field_ty),+
        }

        impl $crate::layout::FieldKind for $ty {
            fn field_type() -> $crate::layout::FieldType {
                $crate::layout::FieldType::Struct { name: stringify!($ty) }
            }
        }

        impl $crate::layout::Layout for $ty {
            const NAME: &'static str = stringify!($ty);

            fn layout() -> $crate::layout::TypeLayout {
                $crate::layout::TypeLayout {
                    name: stringify!($ty),
                    // SAFETY: `type_name` returns the string given to the `ZeroCopySend` derive;
                    // the layout it promises is the one described here and pinned by tests.
                    type_name: unsafe {
                        <$ty as iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>
                            ::type_name()
                    },
                    size: core::mem::size_of::<$ty>(),
                    align: core::mem::align_of::<$ty>(),
                    fields: vec![$(
                        $crate::layout::Field::of(
                            stringify!($field),
                            core::mem::offset_of!($ty, $field),
                            |s: &$ty| &s.$field,
                        )
                        // `as text`: `Field::text`.
                        $(.$marker())?
                    ),+],
                }
            }
        }

        impl $ty {
            $($($crate::layout::ipc_type!(@$marker $field);)?)+
        }
    };
}
pub(crate) use ipc_type;

/// Named constants of one flag or enumeration field.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ConstantGroup {
    #[serde(skip)]
    pub name: &'static str,
    /// `flags` (bits, combined with `|`) or `enum` (one value at a time).
    pub kind: &'static str,
    /// The primitive type of the field that holds them.
    #[serde(rename = "type")]
    pub ty: &'static str,
    /// Every constant, by value.
    pub values: Vec<Constant>,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Constant {
    pub name: String,
    pub value: u64,
}

/// Describes a group of named constants: `describe_constants!(flags FaultFlags: u64 { … })`.
macro_rules! describe_constants {
    (flags $group:ident : $t:ident { $($name:ident),+ $(,)? }) => {
        describe_constants!(@ "flags", $group, $t, $($name),+)
    };
    (enum $group:ident : $t:ident { $($name:ident),+ $(,)? }) => {
        describe_constants!(@ "enum", $group, $t, $($name),+)
    };
    (@ $kind:literal, $group:ident, $t:ident, $($name:ident),+) => {
        $crate::layout::ConstantGroup::new(
            stringify!($group),
            $kind,
            stringify!($t),
            vec![$((stringify!($name).to_string(), {
                let value: $t = $group::$name;
                u64::from(value)
            })),+],
        )
    };
}

impl ConstantGroup {
    pub(crate) fn new(
        name: &'static str,
        kind: &'static str,
        ty: &'static str,
        values: Vec<(String, u64)>,
    ) -> Self {
        let mut values: Vec<Constant> = values
            .into_iter()
            .map(|(name, value)| Constant { name, value })
            .collect();
        values.sort_by(|a, b| a.value.cmp(&b.value).then_with(|| a.name.cmp(&b.name)));
        Self {
            name,
            kind,
            ty,
            values,
        }
    }
}

/// Every IPC type, by Rust name.
pub fn types() -> Vec<TypeLayout> {
    use crate::*;
    macro_rules! layouts {
        ($($ty:ident),+ $(,)?) => { vec![$($ty::layout()),+] };
    }
    let mut all = layouts! {
        ChassisState, MotionState, OdometryState, SystemState, MotorState, BmsState, RcState,
        LightsState, RangesState, ImuState, LiftState, PanTiltState, GpsFix, CommandEcho,
        LinkStats, VelocityRequest, BodyVelocity, SourceStatus, LockStatus, MuxStatus, BusFrame,
        ControlRequest, ControlResponse, SimRequest, SafetyStatus, RobotDescription, MotionLimits,
        Geometry, BatteryLevels, OdometryVariance, SensorDescription, JointDescription,
        SourceDescription,
    };
    all.sort_by_key(|t| t.name);
    all
}

/// Every group of flag and enumeration constants, by name.
pub fn constants() -> Vec<ConstantGroup> {
    use crate::*;
    let mut all = vec![
        describe_constants!(flags LinkFlags: u32 {
            CHASSIS_SILENT, BUS_DOWN, COMMAND_MODE, RC_AUTHORITY, STEERING_ZERO_PENDING,
            GPS_DOWN, SILENT_MODE, CAN_ERROR_PASSIVE, CAN_BUS_OFF, REMOTE_LOST,
        }),
        describe_constants!(enum ControlMode: u8 { UNKNOWN, STANDBY, COMMAND, REMOTE, SERIAL }),
        describe_constants!(enum WireProtocol: u8 { OWN, V1, V2, DETECTING }),
        describe_constants!(enum ControllerState: u8 {
            UNKNOWN, ERROR_ACTIVE, ERROR_WARNING, ERROR_PASSIVE, BUS_OFF,
        }),
        describe_constants!(flags DriverStatus: u8 {
            SUPPLY_UNDER_VOLTAGE, MOTOR_OVER_TEMPERATURE, DRIVER_OVER_CURRENT,
            DRIVER_OVER_TEMPERATURE, SENSOR_FAULT, DRIVER_ERROR, ENABLED,
        }),
        describe_constants!(flags ClampFlags: u32 {
            LINEAR_LIMIT, LINEAR_LIMIT_STEERING, STEER_LIMIT, ANGULAR_LIMIT, LATERAL_UNSUPPORTED,
            TURN_IN_PLACE_UNACHIEVABLE, TURN_RADIUS_LIMIT, ACCELERATION_LIMIT,
            CONFIG_SPEED_LIMIT, QUANTISED, CHASSIS_NOT_READY, SAFETY_LIMIT, SPEED_LIMIT,
        }),
        describe_constants!(enum ZeroReason: u8 {
            NONE, NO_ACTIVE_SOURCE, REQUIRED_SOURCE_STALE, LOCKED, STARTING, AWAITING_ZERO, HELD,
        }),
        describe_constants!(enum Stop: u8 {
            NONE, SERVICE_START, LOCK_RELEASED, REQUIRED_SOURCE, BUS, CHASSIS_ESTOP,
            REMOTE_CONTROL, CHASSIS_FAULT,
        }),
        describe_constants!(flags SourceFlags: u8 {
            REQUIRED, FRESH, ACTIVE, HEARTBEAT, BLOCKED, LIMITING, REMOTE, AWAITING_ZERO,
        }),
        describe_constants!(enum StopCategory: u8 { CUT, BRAKE_THEN_CUT, HOLD }),
        describe_constants!(enum DriveState: u8 { ENABLED, BRAKING, CUT, CANNOT_CUT }),
        describe_constants!(flags RequestFlags: u32 {
            STEER, HEARTBEAT, LIMIT, SPEED_LIMIT, CATEGORY_0, CATEGORY_1, CATEGORY_2,
        }),
        describe_constants!(enum ControlKind: u8 {
            MODE, BRAKE, CLEAR_FAULTS, LIGHTS, OFF_ROAD, LIFT, SERVOS, POWER, STEERING_ZERO,
            LOCK_RELEASE, SILENT, LOCK_ENGAGE, SPEED_LIMIT, KEEP,
        }),
        describe_constants!(enum FaultClear: u8 {
            ALL, MOTOR_1_COMM, MOTOR_2_COMM, MOTOR_3_COMM, MOTOR_4_COMM, BATTERY_UNDER_VOLTAGE,
            BATTERY_OVER_VOLTAGE, RC_LINK, FRONT_STEERING_ENCODER, REAR_STEERING_ENCODER,
            OVER_CURRENT, OVER_TEMPERATURE,
        }),
        describe_constants!(enum LightMode: u8 { OFF, ON, BREATHING, CUSTOM }),
        describe_constants!(enum ControlStatus: u8 { OK, REFUSED, UNSUPPORTED, INVALID, TIMEOUT }),
        describe_constants!(enum SimKind: u8 {
            MOTOR_DRIVER_LOSS, BATTERY, BUMPER, RC_TAKEOVER, REBOOT, SILENCE, GARBAGE,
            BAD_CHECKSUMS, OBSTACLE_AHEAD, OBSTACLE_BEHIND, FLOOD, ESTOP_SWITCH, RUNAWAY, GAIN, TRUTH,
        }),
        describe_constants!(enum SimTruthPage: u8 { MOTION, INJECTED }),
        describe_constants!(enum Kinematics: u8 {
            DIFFERENTIAL, SKID_STEER, TRACKED, OMNI, ACKERMANN, DUAL_ACKERMANN, FOUR_WHEEL_STEER,
        }),
        describe_constants!(enum BusKind: u8 { CAN, RS232 }),
        describe_constants!(flags DescriptionFlags: u8 {
            SIMULATED, BRAKE, LIGHTS, LATERAL, SAFETY_REQUIRED,
        }),
        describe_constants!(enum SensorKind: u8 { ULTRASONIC, INFRARED, IMU, GPS, BUMPER }),
        describe_constants!(enum JointSource: u8 { FRONT_STEER, REAR_STEER, WHEEL }),
        describe_constants!(enum FrameDirection: u8 { RX, TX }),
        describe_constants!(enum FrameKind: u8 { CAN, SERIAL, GPS }),
        describe_constants!(enum SafetyRule: u8 {
            FAULT, BATTERY, STALE, BUMPER, ULTRASONIC, IR, SPEED, OPERATOR, RUNAWAY, DIRECTION,
            FOLLOWING, LIMIT,
        }),
        describe_constants!(enum SafetyAction: u8 { NONE, SLOW, STOP, LATCH }),
        describe_constants!(enum EstopState: u8 {
            UNKNOWN, FREE, HELD_BY_MONITOR, HELD_BY_OPERATOR, HELD_BY_OTHER,
        }),
        describe_constants!(enum SafetyEvent: u8 { NONE, TRIGGER, RELEASE, UNLATCH }),
        describe_constants!(enum Unfollowed: u8 {
            NONE, UNREPORTED, BUS_SILENT, CHASSIS_ESTOP, REMOTE_CONTROL, STANDBY, SERIAL_MODE,
            DRIVER_FAULT, DRIVERS_DISABLED, PARKING_BRAKE,
        }),
        // Constants of one struct's fields, named after the struct.
        describe_constants!(enum SystemState: u8 { BODY_NORMAL, BODY_EMERGENCY_STOP, BODY_EXCEPTION }),
        describe_constants!(enum LockStatus: u8 { HOLDER_NONE, HOLDER_OPERATOR }),
        describe_constants!(enum MuxStatus: u8 { NO_SOURCE }),
        describe_constants!(flags BusFrame: u8 { EXTENDED_ID, REMOTE }),
        describe_constants!(enum SafetyStatus: u8 { NO_RULE }),
        ConstantGroup::new(
            "FaultFlags",
            "flags",
            "u64",
            FaultFlags::ALL
                .iter()
                .map(|&(bit, name)| (name.to_ascii_uppercase(), bit))
                .collect(),
        ),
        // `Group`: the index into `ChassisState::group_stamp_ns`; its bit in `valid_mask` is
        // `1 << index`.
        ConstantGroup::new(
            "Group",
            "enum",
            "u8",
            Group::ALL
                .iter()
                .map(|&g| (g.name().to_ascii_uppercase(), u64::from(g as u8)))
                .collect(),
        ),
    ];
    all.sort_by_key(|g| g.name);
    all
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_zero_copy_type_is_described() {
        let sources = [
            include_str!("state.rs"),
            include_str!("mux.rs"),
            include_str!("request.rs"),
            include_str!("frame.rs"),
            include_str!("control.rs"),
            include_str!("safety.rs"),
            include_str!("description.rs"),
        ];
        let declared: usize = sources
            .iter()
            .map(|s| s.matches("#[type_name(").count())
            .sum();
        assert_eq!(types().len(), declared);
    }

    /// The layouts are pinned by the committed contract, `interfaces/contract.json`: every
    /// type's name with its version, size, alignment and fields with their offsets, sizes and
    /// types. A change to any of them fails here until the contract is regenerated (see
    /// `chassis_ipc::contract`) and its difference reviewed.
    #[test]
    fn every_layout_is_the_one_the_committed_contract_pins() {
        let committed: serde_json::Value =
            serde_json::from_str(include_str!("../contract.json")).unwrap();
        let types: std::collections::BTreeMap<_, _> =
            types().into_iter().map(|t| (t.name, t)).collect();
        let types = serde_json::to_value(types).unwrap();
        for (name, layout) in committed["types"].as_object().unwrap() {
            assert_eq!(&types[name], layout, "{name}");
        }
        assert_eq!(types, committed["types"]);
    }

    #[test]
    fn every_type_covers_its_bytes_and_carries_a_versioned_name() {
        for layout in types() {
            assert_eq!(layout.gap(), None);
            let prefix = format!("chassis::{}.v", layout.name);
            assert!(
                layout.type_name.starts_with(&prefix),
                "{}",
                layout.type_name
            );
        }
    }

    #[test]
    fn every_nested_struct_is_described() {
        let all = types();
        fn structs(ty: &FieldType, out: &mut Vec<&'static str>) {
            match ty {
                FieldType::Struct { name } => out.push(name),
                FieldType::Array { element, .. } => structs(element, out),
                FieldType::Primitive { .. } => {}
            }
        }
        let mut nested = Vec::new();
        for t in &all {
            for f in &t.fields {
                structs(&f.ty, &mut nested);
            }
        }
        assert!(nested.contains(&"MotionState"));
        for name in nested {
            assert!(
                all.iter().any(|t| t.name == name),
                "{name} is not described"
            );
        }
    }

    #[test]
    fn a_missing_field_is_caught() {
        let mut layout = crate::BodyVelocity::layout();
        assert_eq!(layout.gap(), None);
        layout.fields.remove(2);
        assert!(layout.gap().is_some_and(|g| g.contains("steer_rad")));
        let mut layout = crate::BodyVelocity::layout();
        layout.fields.pop();
        assert!(layout.gap().is_some_and(|g| g.contains("20 bytes long")));
    }

    #[test]
    fn fields_carry_their_types_and_lengths() {
        let state = crate::ChassisState::layout();
        let stamps = state
            .fields
            .iter()
            .find(|f| f.name == "group_stamp_ns")
            .unwrap();
        assert_eq!((stamps.offset, stamps.size), (32, 8 * crate::GROUP_SLOTS));
        assert_eq!(stamps.ty.rust(), "[u64; 24]");
        let motors = state.fields.iter().find(|f| f.name == "motors").unwrap();
        assert_eq!(motors.ty.rust(), "[MotorState; 4]");
    }

    #[test]
    fn text_fields_are_byte_arrays_and_the_texts_are_marked() {
        let byte_array = |f: &Field| {
            matches!(&f.ty, FieldType::Array { element, .. }
                if **element == FieldType::Primitive { primitive: "u8" })
        };
        let mut text = Vec::new();
        for layout in types() {
            for field in layout.fields.iter().filter(|f| f.text) {
                assert!(byte_array(field), "{}.{}", layout.name, field.name);
                text.push(format!("{}.{}", layout.name, field.name));
            }
        }
        for marked in [
            "RobotDescription.kind_name",
            "LockStatus.name",
            "SafetyStatus.last_text",
        ] {
            assert!(
                text.iter().any(|t| t == marked),
                "{marked} is not marked as text"
            );
        }
        let frame = crate::BusFrame::layout();
        assert!(
            frame.fields.iter().all(|f| !f.text),
            "a frame's data is bytes"
        );
    }

    #[test]
    fn constant_groups_have_unique_names_and_flags_single_bits() {
        for group in constants() {
            let mut names: Vec<_> = group.values.iter().map(|c| c.name.as_str()).collect();
            names.sort_unstable();
            names.dedup();
            assert_eq!(names.len(), group.values.len(), "{}", group.name);
            if group.kind == "flags" {
                for c in &group.values {
                    assert_eq!(c.value.count_ones(), 1, "{}::{}", group.name, c.name);
                }
            }
        }
        let faults = constants()
            .into_iter()
            .find(|g| g.name == "FaultFlags")
            .unwrap();
        assert_eq!(faults.values.len(), crate::FaultFlags::ALL.len());
        assert_eq!(faults.values[0].name, "HEARTBEAT_LOST");
    }

    /// The contract lists each group's constants by hand: one the group names for logs and JSON
    /// but the contract leaves out is a constant the Python mirror and other languages lack.
    #[test]
    fn the_contract_lists_every_constant_a_group_names() {
        use crate::*;
        let groups = constants();
        let values = |group: &str| -> Vec<u64> {
            let mut v: Vec<u64> = groups
                .iter()
                .find(|g| g.name == group)
                .unwrap_or_else(|| panic!("{group} is not in the contract"))
                .values
                .iter()
                .map(|c| c.value)
                .collect();
            v.sort_unstable();
            v
        };
        macro_rules! every {
            ($($table:ident :: $names:ident),+ $(,)?) => {$({
                let mut named: Vec<u64> =
                    $table::$names.iter().map(|&(v, _)| u64::from(v)).collect();
                named.sort_unstable();
                assert_eq!(values(stringify!($table)), named, stringify!($table));
            })+};
        }
        every!(
            BusKind::NAMES,
            ControlKind::NAMES,
            ControlMode::NAMES,
            ControlStatus::NAMES,
            ControllerState::NAMES,
            EstopState::NAMES,
            FaultClear::NAMES,
            FrameDirection::NAMES,
            FrameKind::NAMES,
            JointSource::NAMES,
            Kinematics::NAMES,
            LightMode::NAMES,
            SafetyAction::NAMES,
            SafetyEvent::NAMES,
            SafetyRule::NAMES,
            SensorKind::NAMES,
            SimKind::NAMES,
            SimTruthPage::NAMES,
            Stop::NAMES,
            StopCategory::NAMES,
            DriveState::NAMES,
            Unfollowed::NAMES,
            WireProtocol::NAMES,
            ZeroReason::NAMES,
            ClampFlags::ALL,
            DescriptionFlags::ALL,
            DriverStatus::ALL,
            FaultFlags::ALL,
            LinkFlags::ALL,
            RequestFlags::ALL,
            SourceFlags::ALL,
        );
    }
}
