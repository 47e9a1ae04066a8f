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
    macro_rules! groups {
        ($($group:ident),+ $(,)?) => { vec![$($group::constant_group()),+] };
    }
    let mut all = groups![
        BusKind,
        ClampFlags,
        ControlKind,
        ControlMode,
        ControlStatus,
        ControllerState,
        DescriptionFlags,
        DriveState,
        DriverStatus,
        EstopState,
        FaultClear,
        FaultFlags,
        FrameDirection,
        FrameKind,
        JointSource,
        Kinematics,
        LightMode,
        LinkFlags,
        RequestFlags,
        SafetyAction,
        SafetyEvent,
        SafetyRule,
        SensorKind,
        SimKind,
        SimTruthPage,
        SourceFlags,
        Stop,
        StopCategory,
        Unfollowed,
        WireProtocol,
        ZeroReason,
    ];
    // Constants of the samples themselves.
    all.extend([
        describe_constants!(enum SystemState: u8 { BODY_NORMAL, BODY_EMERGENCY_STOP, BODY_EXCEPTION }),
        describe_constants!(enum LockStatus: u8 { HOLDER_NONE, HOLDER_OPERATOR }),
        describe_constants!(enum MuxStatus: u8 { NO_SOURCE }),
        describe_constants!(flags BusFrame: u8 { EXTENDED_ID, REMOTE }),
        describe_constants!(enum SafetyStatus: u8 { NO_RULE }),
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
    ]);
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
}
