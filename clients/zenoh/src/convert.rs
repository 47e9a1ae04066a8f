//! The Zenoh side of the contract: key expressions, encodings and the fixed-layout payloads.
//!
//! Every binary payload is the IPC type's bytes exactly as they lie in shared memory, with the
//! encoding `application/octet-stream;<type name>`, e.g.
//! `application/octet-stream;chassis::ChassisState.v4`. The bytes and the check of what arrives
//! from another computer are [`chassis_client::payload`]'s (sans-IO, fuzzed); [`Wire`] only
//! carries them in Zenoh's [`Encoding`]. A velocity request from another computer is parsed
//! into a [`ValidRequest`] where it arrives ([`Wire::decode_request`]).

use chassis_client::payload::{Payload, PayloadError, PayloadType};
use chassis_client::{InvalidVelocity, ServiceKind, ValidRequest, VelocityRequest, service_name};
use zenoh::bytes::Encoding;

/// The encoding of a payload carrying `T` (one or several, back to back).
pub fn encoding<T: Payload>() -> Encoding {
    Encoding::APPLICATION_OCTET_STREAM.with_schema(T::layout().type_name)
}

/// A payload type with its encoding, measured once.
#[derive(Debug, Clone)]
pub struct Wire<T> {
    encoding: Encoding,
    payload: PayloadType<T>,
}

impl<T: Payload> Wire<T> {
    pub fn new() -> Self {
        Self {
            encoding: encoding::<T>(),
            payload: PayloadType::new(),
        }
    }

    pub fn encoding(&self) -> Encoding {
        self.encoding.clone()
    }

    /// The values a payload carries, after checking its encoding, its length and each value.
    pub fn decode_all(&self, encoding: &Encoding, bytes: &[u8]) -> Result<Vec<T>, PayloadError> {
        self.payload.decode_all(&encoding.to_string(), bytes)
    }

    /// The one value a payload carries.
    pub fn decode(&self, encoding: &Encoding, bytes: &[u8]) -> Result<T, PayloadError> {
        self.payload.decode(&encoding.to_string(), bytes)
    }
}

/// Why a velocity request from another computer is not passed on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RequestError {
    /// Not the type, or cut.
    #[error(transparent)]
    Payload(#[from] PayloadError),
    /// A NaN, an infinity or a negative envelope.
    #[error(transparent)]
    Invalid(#[from] InvalidVelocity),
}

impl Wire<VelocityRequest> {
    /// The one request a payload carries, parsed: where a velocity from another computer
    /// enters this one.
    pub fn decode_request(
        &self,
        encoding: &Encoding,
        bytes: &[u8],
    ) -> Result<ValidRequest, RequestError> {
        Ok(ValidRequest::try_from(self.decode(encoding, bytes)?)?)
    }
}

impl<T: Payload> Default for Wire<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// The encoding of a clock reading: `CLOCK_MONOTONIC` ns, 8 bytes little-endian.
pub fn clock_encoding() -> Encoding {
    Encoding::APPLICATION_OCTET_STREAM.with_schema("chassis::MonotonicNs")
}

/// A clock reading from its payload, if it is one.
pub fn clock_reading(encoding: &Encoding, bytes: &[u8]) -> Option<u64> {
    if *encoding != clock_encoding() {
        return None;
    }
    Some(u64::from_le_bytes(bytes.try_into().ok()?))
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
    /// `chassis/<name>/robot`: the robot's description, put when it changes and answered to a
    /// query (a mirror that starts or reconnects later asks for it).
    pub description: String,
    /// `chassis/<name>/clock`: the operator side's `CLOCK_MONOTONIC`, answered to the robot
    /// side's queries (8 bytes, little-endian ns), so the robot side knows how old a request is.
    pub clock: String,
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
            description: service_name(name, ServiceKind::Description),
            clock: format!("chassis/{name}/clock"),
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
    use chassis_client::{
        BusFrame, ChassisState, ControlRequest, ControlResponse, MuxStatus, RobotDescription,
    };
    use zerocopy::IntoBytes as _;

    #[test]
    fn zenoh_encodings_are_the_payload_media_types() {
        fn same<T: Payload>() {
            assert_eq!(
                Wire::<T>::new().encoding().to_string(),
                PayloadType::<T>::new().media_type()
            );
        }
        same::<VelocityRequest>();
        same::<ChassisState>();
        same::<MuxStatus>();
        same::<BusFrame>();
        same::<ControlRequest>();
        same::<ControlResponse>();
        same::<RobotDescription>();
        let wire = Wire::<VelocityRequest>::new();
        let request = VelocityRequest::twist(0.5, -0.25);
        assert_eq!(
            wire.decode(&wire.encoding(), request.as_bytes()),
            Ok(request)
        );
        assert!(matches!(
            wire.decode(&Wire::<ChassisState>::new().encoding(), request.as_bytes()),
            Err(PayloadError::MediaType { .. })
        ));
        assert_eq!(
            wire.decode_request(&wire.encoding(), request.as_bytes()),
            Ok(ValidRequest::try_from(request).unwrap())
        );
        let nan = VelocityRequest::twist(f32::NAN, 0.0);
        assert!(matches!(
            wire.decode_request(&wire.encoding(), nan.as_bytes()),
            Err(RequestError::Invalid(_))
        ));
    }

    #[test]
    fn a_clock_reading_is_eight_bytes_under_its_encoding() {
        let ns: u64 = 1_234_567_890_123;
        assert_eq!(
            clock_reading(&clock_encoding(), &ns.to_le_bytes()),
            Some(ns)
        );
        assert_eq!(
            clock_reading(&clock_encoding(), &ns.to_le_bytes()[..7]),
            None
        );
        assert_eq!(
            clock_reading(&Wire::<ChassisState>::new().encoding(), &ns.to_le_bytes()),
            None
        );
    }

    #[test]
    fn keys_are_the_service_names() {
        let keys = Keys::new("titan");
        assert_eq!(keys.state, "chassis/titan/state");
        assert_eq!(keys.state_json, "chassis/titan/state/json");
        assert_eq!(keys.cmd("remote"), "chassis/titan/cmd/remote");
        assert_eq!(keys.cmd_any, "chassis/titan/cmd/*");
        assert_eq!(keys.description, "chassis/titan/robot");
        assert_eq!(keys.source_of("chassis/titan/cmd/remote"), Some("remote"));
        assert_eq!(keys.source_of("chassis/titan/cmd/"), None);
        assert_eq!(keys.source_of("chassis/other/cmd/remote"), None);
    }
}
