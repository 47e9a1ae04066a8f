//! IPC samples as bytes that cross a network: what the Zenoh bridge puts on the wire and the one
//! decoder of what it takes from another computer.
//!
//! A payload carries one or several values of one type back to back, each exactly as it lies in
//! shared memory (native byte order, the layout `interfaces/contract.json` describes), under the
//! media type `application/octet-stream;<type name>`, e.g.
//! `application/octet-stream;chassis::ChassisState.v4`: a reader checks the type name (and so the
//! layout version) before it reads a byte, then the length, then every value.
//!
//! Every bit pattern is a value of these types, but not every value may cross: a
//! [`RobotDescription`] counting more entries than its lists hold is refused here
//! ([`Payload::refusal`]). A [`VelocityRequest`] is read as bytes here and parsed by its reader
//! into a [`crate::ValidRequest`], the one check of its numbers.

use thiserror::Error;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use crate::layout::Layout;
use crate::{
    BusFrame, ChassisState, ControlRequest, ControlResponse, MAX_JOINTS, MAX_SENSORS, MAX_SOURCES,
    MuxStatus, RobotDescription, SafetyStatus, SimRequest, VelocityRequest,
};

/// The media type of every payload, before `;<type name>`.
pub const OCTET_STREAM: &str = "application/octet-stream";

/// Why a payload was not taken.
#[derive(Debug, Clone, Error, PartialEq, Eq)]
pub enum PayloadError {
    #[error("media type '{got}' is not the expected '{expected}'")]
    MediaType { got: String, expected: String },
    #[error("{len} bytes, not a multiple of the {size} bytes of {type_name}")]
    Size {
        len: usize,
        size: usize,
        type_name: &'static str,
    },
    #[error("{count} values of {type_name}, not one")]
    Count {
        count: usize,
        type_name: &'static str,
    },
    #[error("value {index} of {type_name} refused: {reason}")]
    Refused {
        index: usize,
        type_name: &'static str,
        reason: &'static str,
    },
}

/// An IPC type that may cross a network as a payload.
pub trait Payload:
    Layout + FromBytes + IntoBytes + Immutable + KnownLayout + Copy + core::fmt::Debug
{
    /// Why this value must not be taken from another computer, if it must not.
    fn refusal(&self) -> Option<&'static str> {
        None
    }
}

impl Payload for ChassisState {}
impl Payload for MuxStatus {}
impl Payload for BusFrame {}
impl Payload for ControlRequest {}
impl Payload for ControlResponse {}
impl Payload for SimRequest {}
impl Payload for SafetyStatus {}
impl Payload for VelocityRequest {}

impl Payload for RobotDescription {
    fn refusal(&self) -> Option<&'static str> {
        (usize::from(self.sensor_count) > MAX_SENSORS
            || usize::from(self.joint_count) > MAX_JOINTS
            || usize::from(self.source_count) > MAX_SOURCES)
            .then_some("a count of sensors, joints or sources beyond its list")
    }
}

/// `application/octet-stream;<type name>` of `T`.
pub fn media_type<T: Layout>() -> String {
    format!("{OCTET_STREAM};{}", T::layout().type_name)
}

/// The payloads of one type: its media type, measured once.
#[derive(Debug, Clone)]
pub struct PayloadType<T> {
    media_type: String,
    type_name: &'static str,
    _t: core::marker::PhantomData<fn() -> T>,
}

impl<T: Payload> Default for PayloadType<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Payload> PayloadType<T> {
    pub fn new() -> Self {
        Self {
            media_type: media_type::<T>(),
            type_name: T::layout().type_name,
            _t: core::marker::PhantomData,
        }
    }

    /// `application/octet-stream;<type name>`.
    pub fn media_type(&self) -> &str {
        &self.media_type
    }

    /// The bytes of `values`, back to back.
    pub fn encode(values: &[T]) -> &[u8] {
        values.as_bytes()
    }

    /// The values a payload carries (none for an empty one), after checking its media type,
    /// its length and every value. One refused value refuses the payload.
    pub fn decode_all(&self, media_type: &str, bytes: &[u8]) -> Result<Vec<T>, PayloadError> {
        if media_type != self.media_type {
            return Err(PayloadError::MediaType {
                got: media_type.to_string(),
                expected: self.media_type.clone(),
            });
        }
        let size = size_of::<T>();
        let size_error = || PayloadError::Size {
            len: bytes.len(),
            size,
            type_name: self.type_name,
        };
        if !bytes.len().is_multiple_of(size) {
            return Err(size_error());
        }
        bytes
            .chunks_exact(size)
            .enumerate()
            .map(|(index, chunk)| {
                let value = T::read_from_bytes(chunk).map_err(|_| size_error())?;
                match value.refusal() {
                    None => Ok(value),
                    Some(reason) => Err(PayloadError::Refused {
                        index,
                        type_name: self.type_name,
                        reason,
                    }),
                }
            })
            .collect()
    }

    /// The one value a payload carries.
    pub fn decode(&self, media_type: &str, bytes: &[u8]) -> Result<T, PayloadError> {
        let values = self.decode_all(media_type, bytes)?;
        match values.as_slice() {
            [one] => Ok(*one),
            _ => Err(PayloadError::Count {
                count: values.len(),
                type_name: self.type_name,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_payload_names_its_type_and_round_trips() {
        let requests = PayloadType::<VelocityRequest>::new();
        assert_eq!(
            requests.media_type(),
            "application/octet-stream;chassis::VelocityRequest.v3"
        );
        let request = VelocityRequest::twist(0.5, -0.25);
        let bytes = PayloadType::encode(core::slice::from_ref(&request));
        assert_eq!(requests.decode(requests.media_type(), bytes), Ok(request));
        let two = [request, VelocityRequest::heartbeat()];
        assert_eq!(
            requests.decode_all(requests.media_type(), PayloadType::encode(&two)),
            Ok(two.to_vec())
        );
        assert_eq!(
            requests.decode(requests.media_type(), PayloadType::encode(&two)),
            Err(PayloadError::Count {
                count: 2,
                type_name: "chassis::VelocityRequest.v3"
            })
        );
        assert_eq!(requests.decode_all(requests.media_type(), &[]), Ok(vec![]));
    }

    #[test]
    fn another_type_or_a_cut_payload_is_refused() {
        let states = PayloadType::<ChassisState>::new();
        let requests = PayloadType::<VelocityRequest>::new();
        let bytes = ChassisState::default();
        assert!(matches!(
            requests.decode(states.media_type(), bytes.as_bytes()),
            Err(PayloadError::MediaType { .. })
        ));
        assert!(matches!(
            requests.decode(requests.media_type(), &[0; 7]),
            Err(PayloadError::Size { len: 7, .. })
        ));
        assert!(matches!(
            states.decode(
                states.media_type(),
                &bytes.as_bytes()[..size_of::<ChassisState>() - 1]
            ),
            Err(PayloadError::Size { .. })
        ));
    }

    #[test]
    fn only_a_description_beyond_its_lists_is_refused_a_request_is_parsed_by_its_reader() {
        let requests = PayloadType::<VelocityRequest>::new();
        let media = requests.media_type();
        let nan = VelocityRequest::twist(f32::NAN, 0.0);
        let read = requests.decode(media, nan.as_bytes());
        assert!(matches!(read, Ok(r) if r.as_bytes() == nan.as_bytes()));
        assert!(read.is_ok_and(|r| crate::ValidRequest::try_from(r).is_err()));
        // A description counts no more entries than its lists hold; its unknowns are NaN.
        let descriptions = PayloadType::<RobotDescription>::new();
        let mut d = RobotDescription::default();
        assert!(
            descriptions
                .decode(descriptions.media_type(), d.as_bytes())
                .is_ok()
        );
        d.joint_count = crate::MAX_JOINTS as u8 + 1;
        assert!(matches!(
            descriptions.decode(descriptions.media_type(), d.as_bytes()),
            Err(PayloadError::Refused { index: 0, .. })
        ));
        // Other types carry whatever they carry: a state with a NaN is a state.
        let mut state = ChassisState::default();
        state.motion.linear_mps = f32::NAN;
        let states = PayloadType::<ChassisState>::new();
        assert!(states.decode(states.media_type(), state.as_bytes()).is_ok());
    }
}
