//! A state as bytes, to go on from where a recorded run was: the black box keeps the engine's
//! and its driver's state at the start of each stretch of its ring, so that a window whose
//! beginning the ring let go of is replayed from there ([`crate::Driver::snapshot`]).
//!
//! postcard keeps every float bit for bit (NaN included), which a replay checked byte for byte
//! needs; the chassis' zerocopy records go as their bytes ([`raw`]).

use serde::Serialize;
use serde::de::DeserializeOwned;

/// Why a snapshot cannot be taken or read.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// It does not fit what reads it (another version's, or another robot's).
    #[error("a snapshot of the state: {0}")]
    Format(#[from] postcard::Error),
    /// Frames wait to be sent, or publications to be published: a snapshot is taken between
    /// passes, once the engine has drained them (the next pass).
    #[error("frames or publications wait to be handed on")]
    Sending,
    /// It was taken of another configuration than the one it is restored on.
    #[error("the snapshot is of another configuration: {0}")]
    Mismatch(String),
}

/// `value` as bytes.
pub fn save<T: Serialize + ?Sized>(value: &T) -> Result<Vec<u8>, SnapshotError> {
    Ok(postcard::to_allocvec(value)?)
}

/// The value `bytes` were saved from.
pub fn load<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, SnapshotError> {
    Ok(postcard::from_bytes(bytes)?)
}

/// A fixed-layout record of the IPC contract as its bytes (`#[serde(with = "snapshot::raw")]`).
pub mod raw {
    use serde::de::Error;
    use serde::{Deserialize, Deserializer, Serializer};
    use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

    pub fn serialize<T: IntoBytes + Immutable, S: Serializer>(
        value: &T,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(value.as_bytes())
    }

    pub fn deserialize<'de, T: FromBytes + KnownLayout, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<T, D::Error> {
        let bytes: &[u8] = Deserialize::deserialize(deserializer)?;
        T::read_from_bytes(bytes).map_err(|_| D::Error::custom("a record of another size"))
    }
}

/// A driver's [`crate::Driver::snapshot`] and [`crate::Driver::restore`] as its whole self.
/// The frames `$waiting` holds are not part of it: a driver with frames waiting refuses.
macro_rules! whole_driver {
    ($($waiting:ident)?) => {
        fn snapshot(&self) -> Result<Vec<u8>, $crate::snapshot::SnapshotError> {
            $(if !self.$waiting.is_empty() {
                return Err($crate::snapshot::SnapshotError::Sending);
            })?
            $crate::snapshot::save(self)
        }
        fn restore(&mut self, snapshot: &[u8]) -> Result<(), $crate::snapshot::SnapshotError> {
            *self = $crate::snapshot::load(snapshot)?;
            Ok(())
        }
    };
}
pub(crate) use whole_driver;

/// An optional record of the IPC contract as its bytes (`#[serde(with = "snapshot::raw_option")]`).
pub mod raw_option {
    use serde::de::Error;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};
    use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

    pub fn serialize<T: IntoBytes + Immutable, S: Serializer>(
        value: &Option<T>,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        value
            .as_ref()
            .map(IntoBytes::as_bytes)
            .serialize(serializer)
    }

    pub fn deserialize<'de, T: FromBytes + KnownLayout, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Option<T>, D::Error> {
        Option::<&[u8]>::deserialize(deserializer)?
            .map(|bytes| {
                T::read_from_bytes(bytes).map_err(|_| D::Error::custom("a record of another size"))
            })
            .transpose()
    }
}
