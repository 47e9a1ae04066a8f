//! The Zenoh side of the contract: key expressions, encodings and the fixed-layout payloads.
//!
//! Every binary payload is the IPC type's bytes exactly as they lie in shared memory (native
//! byte order, the layout `interfaces/contract.json` describes), with the encoding
//! `application/octet-stream;<type name>`, e.g. `application/octet-stream;chassis::ChassisState.v2`:
//! a reader checks the type name (and so the layout version) before it reads a byte.

use chassis_client::layout::Layout;
use chassis_client::{ServiceKind, service_name};
use thiserror::Error;
use zenoh::bytes::Encoding;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

/// Why a payload was not taken.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum WireError {
    #[error("encoding '{got}' is not the expected '{expected}'")]
    Encoding { got: String, expected: String },
    #[error("{len} bytes, not a multiple of the {size} bytes of {type_name}")]
    Size {
        len: usize,
        size: usize,
        type_name: &'static str,
    },
}

/// The encoding of a payload carrying `T` (one or several, back to back).
pub fn encoding<T: Layout>() -> Encoding {
    Encoding::APPLICATION_OCTET_STREAM.with_schema(T::layout().type_name)
}

/// A payload type with its encoding, measured once.
#[derive(Debug, Clone)]
pub struct Wire<T> {
    encoding: Encoding,
    text: String,
    type_name: &'static str,
    _t: std::marker::PhantomData<fn() -> T>,
}

impl<T: Layout + FromBytes + IntoBytes + Immutable + KnownLayout + Copy> Wire<T> {
    pub fn new() -> Self {
        let encoding = encoding::<T>();
        Self {
            text: encoding.to_string(),
            encoding,
            type_name: T::layout().type_name,
            _t: std::marker::PhantomData,
        }
    }

    pub fn encoding(&self) -> Encoding {
        self.encoding.clone()
    }

    /// The values a payload carries, after checking its encoding and its length.
    pub fn decode_all(&self, encoding: &Encoding, bytes: &[u8]) -> Result<Vec<T>, WireError> {
        if encoding.to_string() != self.text {
            return Err(WireError::Encoding {
                got: encoding.to_string(),
                expected: self.text.clone(),
            });
        }
        let size = size_of::<T>();
        if !bytes.len().is_multiple_of(size) {
            return Err(WireError::Size {
                len: bytes.len(),
                size,
                type_name: self.type_name,
            });
        }
        Ok(bytes
            .chunks_exact(size)
            .filter_map(|chunk| T::read_from_bytes(chunk).ok())
            .collect())
    }

    /// The one value a payload carries.
    pub fn decode(&self, encoding: &Encoding, bytes: &[u8]) -> Result<T, WireError> {
        let values = self.decode_all(encoding, bytes)?;
        match values.as_slice() {
            [one] => Ok(*one),
            _ => Err(WireError::Size {
                len: bytes.len(),
                size: size_of::<T>(),
                type_name: self.type_name,
            }),
        }
    }
}

impl<T: Layout + FromBytes + IntoBytes + Immutable + KnownLayout + Copy> Default for Wire<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// The key expressions of one robot: the iceoryx2 service names, so that one name means one
/// thing on both sides.
#[derive(Debug, Clone)]
pub struct Keys {
    pub state: String,
    pub state_json: String,
    pub mux: String,
    pub mux_json: String,
    pub frames: String,
    pub control: String,
    /// `chassis/<name>/cmd/*`: every source, for the robot side's one subscriber.
    pub cmd_any: String,
    /// The liveliness token of the robot side.
    pub alive: String,
    name: String,
}

impl Keys {
    pub fn new(name: &str) -> Self {
        let state = service_name(name, ServiceKind::State);
        let mux = service_name(name, ServiceKind::Mux);
        Self {
            state_json: format!("{state}/json"),
            mux_json: format!("{mux}/json"),
            state,
            mux,
            frames: service_name(name, ServiceKind::Frames),
            control: service_name(name, ServiceKind::Control),
            cmd_any: service_name(name, ServiceKind::Cmd("*")),
            alive: format!("chassis/{name}/alive"),
            name: name.to_string(),
        }
    }

    /// `chassis/<name>/cmd/<source>`.
    pub fn cmd(&self, source: &str) -> String {
        service_name(&self.name, ServiceKind::Cmd(source))
    }

    /// The source a `cmd/<source>` key names.
    pub fn source_of<'k>(&self, key: &'k str) -> Option<&'k str> {
        let prefix = service_name(&self.name, ServiceKind::Cmd(""));
        key.strip_prefix(prefix.as_str())
            .filter(|s| !s.is_empty() && !s.contains('/'))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::{ChassisState, VelocityRequest};

    #[test]
    fn payloads_carry_the_type_name_and_are_checked() {
        let wire = Wire::<VelocityRequest>::new();
        assert_eq!(
            wire.encoding().to_string(),
            format!(
                "application/octet-stream;{}",
                VelocityRequest::layout().type_name
            )
        );
        let request = VelocityRequest::twist(0.5, -0.25);
        let decoded = wire
            .decode(&wire.encoding(), request.as_bytes())
            .expect("decodes");
        assert_eq!(decoded, request);
        let state = Wire::<ChassisState>::new();
        assert!(matches!(
            state.decode(&wire.encoding(), ChassisState::default().as_bytes()),
            Err(WireError::Encoding { .. })
        ));
        assert!(matches!(
            wire.decode(&wire.encoding(), &[0; 7]),
            Err(WireError::Size { len: 7, .. })
        ));
        let two = [request, request];
        assert_eq!(
            wire.decode_all(&wire.encoding(), two.as_bytes()),
            Ok(two.to_vec())
        );
    }

    #[test]
    fn keys_are_the_service_names() {
        let keys = Keys::new("titan");
        assert_eq!(keys.state, "chassis/titan/state");
        assert_eq!(keys.state_json, "chassis/titan/state/json");
        assert_eq!(keys.cmd("remote"), "chassis/titan/cmd/remote");
        assert_eq!(keys.cmd_any, "chassis/titan/cmd/*");
        assert_eq!(keys.source_of("chassis/titan/cmd/remote"), Some("remote"));
        assert_eq!(keys.source_of("chassis/titan/cmd/"), None);
        assert_eq!(keys.source_of("chassis/other/cmd/remote"), None);
    }
}
