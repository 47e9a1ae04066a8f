//! Groups of named constants: the flag and enumeration types of the contract.
//!
//! A field that holds bits or one of a few values is a plain integer (`u8`, `u32`, `u64`): the
//! layout stays `#[repr(C)]` and readable from any language. Its constants live on an empty
//! struct named after the group (`LinkFlags::BUS_DOWN`, `ZeroReason::LOCKED`), declared once with
//! [`named_constants!`]: every constant with its value and the name logs and JSON use, so the
//! names can never miss a constant the group has.

/// Declares a group of named constants: an empty struct, one associated constant per entry, the
/// table of them all, and the lookups every group of its kind offers.
///
/// ```ignore
/// named_constants! {
///     /// Why the mux outputs zero.
///     pub enum ZeroReason: u8 {
///         /// A source is active.
///         NONE = 0 => "none",
///         LOCKED = 3 => "locked",
///     }
/// }
/// ```
///
/// - `pub enum Group: u8 { … }` (one value at a time) gives `Group::NAMES`, every
///   `(value, name)` in the order written, `Group::name(value)` (`"unknown"` for a value not
///   listed) and `Group::from_name(name)`.
/// - `pub flags Group: u32 { … }` (bits combined with `|`) gives the same table as `Group::ALL`,
///   `Group::names(bits)` (the names of the set bits, in table order) and `Group::from_name(name)`.
///
/// The contract (`layout::constants`) lists the constants by their Rust names
/// (`Group::constant_group()`).
macro_rules! named_constants {
    (
        $(#[$meta:meta])*
        pub $kind:ident $group:ident : $t:ident {
            $($(#[$doc:meta])* $name:ident = $value:expr => $text:literal),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy)]
        pub struct $group;
        impl $group {
            $($(#[$doc])* pub const $name: $t = $value;)+

            /// The group as the contract lists it (`layout::constants`): every constant by its
            /// Rust name.
            pub(crate) fn constant_group() -> $crate::layout::ConstantGroup {
                $crate::layout::ConstantGroup::new(
                    stringify!($group),
                    stringify!($kind),
                    stringify!($t),
                    vec![$((stringify!($name).to_string(), u64::from(Self::$name))),+],
                )
            }

            /// For the tests: every constant's Rust name, value and name.
            #[cfg(test)]
            pub(crate) fn spellings() -> Vec<(&'static str, u64, &'static str)> {
                vec![$((stringify!($name), u64::from(Self::$name), $text)),+]
            }
        }
        $crate::named::named_constants!(@$kind $group: $t [$(($name, $text)),+]);
    };
    (@enum $group:ident : $t:ident [$(($name:ident, $text:literal)),+]) => {
        impl $group {
            /// Every value with its name, in declaration order.
            pub const NAMES: [($t, &'static str); [$($text),+].len()] = [$((Self::$name, $text)),+];

            /// The name of `value`, `unknown` for a value not listed.
            pub fn name(value: $t) -> &'static str {
                $crate::named::name_of(&Self::NAMES, value)
            }

            /// The value called `name`, if any.
            pub fn from_name(name: &str) -> Option<$t> {
                $crate::named::value_of(&Self::NAMES, name)
            }
        }
    };
    (@flags $group:ident : $t:ident [$(($name:ident, $text:literal)),+]) => {
        impl $group {
            /// Every flag with its name, in declaration (bit) order.
            pub const ALL: [($t, &'static str); [$($text),+].len()] = [$((Self::$name, $text)),+];

            /// Names of the set bits, for logs and JSON.
            pub fn names(bits: $t) -> Vec<&'static str> {
                $crate::named::names_of(&Self::ALL, bits)
            }

            /// The bit called `name`, if any.
            pub fn from_name(name: &str) -> Option<$t> {
                $crate::named::value_of(&Self::ALL, name)
            }
        }
    };
}
pub(crate) use named_constants;

/// The name of `value` in `table`, `unknown` when it has none.
pub(crate) fn name_of<T: PartialEq>(table: &[(T, &'static str)], value: T) -> &'static str {
    table
        .iter()
        .find(|(v, _)| *v == value)
        .map_or("unknown", |(_, name)| name)
}

/// The value called `name` in `table`.
pub(crate) fn value_of<T: Copy>(table: &[(T, &'static str)], name: &str) -> Option<T> {
    table.iter().find(|(_, n)| *n == name).map(|(v, _)| *v)
}

/// The names of the bits of `table` set in `bits`, in table order.
pub(crate) fn names_of<T: Copy + Into<u64>>(
    table: &[(T, &'static str)],
    bits: T,
) -> Vec<&'static str> {
    let bits: u64 = bits.into();
    table
        .iter()
        .filter(|(bit, _)| bits & (*bit).into() != 0)
        .map(|(_, name)| *name)
        .collect()
}

#[cfg(test)]
mod tests {
    type Spellings = Vec<(&'static str, u64, &'static str)>;

    /// Every group declared with `named_constants!`: its Rust name and its spellings.
    fn groups() -> Vec<(&'static str, Spellings)> {
        use crate::*;
        macro_rules! all {
            ($($group:ident),+ $(,)?) => {
                vec![$((stringify!($group), $group::spellings())),+]
            };
        }
        all![
            LinkFlags,
            ControllerState,
            ControlMode,
            WireProtocol,
            FaultFlags,
            DriverStatus,
            ClampFlags,
            ZeroReason,
            Stop,
            StopCategory,
            DriveState,
            SourceFlags,
            RequestFlags,
            ControlKind,
            FaultClear,
            LightMode,
            ControlStatus,
            SimTruthPage,
            SimKind,
            Kinematics,
            BusKind,
            DescriptionFlags,
            SensorKind,
            JointSource,
            SafetyRule,
            SafetyAction,
            EstopState,
            SafetyEvent,
            Unfollowed,
            FrameDirection,
            FrameKind,
        ]
    }

    #[test]
    fn every_name_is_unique_in_its_group_and_spells_its_constant() {
        // Their names are phrases or shorter than the constants: only unique.
        let phrased = ["EstopState", "FaultClear"];
        for (group, spellings) in groups() {
            let mut names: Vec<&str> = spellings.iter().map(|(_, _, name)| *name).collect();
            names.sort_unstable();
            names.dedup();
            assert_eq!(names.len(), spellings.len(), "{group}: a name twice");
            if phrased.contains(&group) {
                continue;
            }
            for (rust, _, name) in &spellings {
                assert_eq!(
                    name.replace('-', "_"),
                    rust.to_ascii_lowercase(),
                    "{group}::{rust} is called {name:?}"
                );
            }
        }
    }

    #[test]
    fn names_lead_back_to_their_values() {
        use crate::{ClampFlags, FaultClear, LinkFlags, SafetyRule, SourceFlags};
        assert_eq!(FaultClear::name(FaultClear::RC_LINK), "rc-link");
        assert_eq!(FaultClear::name(200), "unknown");
        assert_eq!(FaultClear::from_name("rc-link"), Some(FaultClear::RC_LINK));
        assert_eq!(FaultClear::from_name("rc_link"), None);
        assert_eq!(
            LinkFlags::names(LinkFlags::REMOTE_LOST | LinkFlags::BUS_DOWN),
            ["bus_down", "remote_lost"]
        );
        assert_eq!(LinkFlags::names(0), Vec::<&str>::new());
        assert_eq!(
            ClampFlags::from_name("quantised"),
            Some(ClampFlags::QUANTISED)
        );
        assert_eq!(
            SourceFlags::names(SourceFlags::AWAITING_ZERO),
            ["awaiting_zero"]
        );
        assert_eq!(SafetyRule::name(SafetyRule::OPERATOR), "operator");
    }
}
