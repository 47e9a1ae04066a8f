//! [`ValidRequest`] and [`Velocity`]: a velocity that crossed a process boundary, parsed once
//! into a type that cannot hold a NaN or an infinity.
//!
//! [`VelocityRequest`] and [`BodyVelocity`] are plain bytes in shared memory or on a network: a
//! foreign process may write anything into them. Where a velocity enters a process it is parsed
//! once — chassisd reading a source's request, the client library sending one, a bridge decoding
//! a ROS 2 `cmd_vel`, a Foxglove Twist or a Zenoh payload, `chassis encode` reading its
//! arguments — and everything behind that edge (the mux, the drivers, the per-robot planning of
//! a motion frame) takes these types and checks nothing again. The encoders' range check stays
//! as the last line before the wire.

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use thiserror::Error;
use zerocopy::{FromBytes, IntoBytes};

use crate::{BodyVelocity, RequestFlags, VelocityRequest};

/// Why a velocity or a request was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum InvalidVelocity {
    /// A NaN or an infinity (in any number of a request, used or not).
    #[error("{field} is not a finite number")]
    NotFinite { field: &'static str },
    /// A negative bound of a speed envelope ([`RequestFlags::LIMIT`]).
    #[error("{field} is negative (an envelope bound is 0 or more)")]
    NegativeLimit { field: &'static str },
    /// A speed limit ([`RequestFlags::SPEED_LIMIT`]) of zero or less: a stop is a lock, and no
    /// limit is the operator's to restore.
    #[error("speed_limit_mps is 0 or negative (a speed limit is more than 0 m/s)")]
    NonPositiveSpeedLimit,
}

/// `Ok` when every value is finite, else the first field that is not.
fn finite(values: &[(&'static str, f32)]) -> Result<(), InvalidVelocity> {
    match values.iter().find(|(_, v)| !v.is_finite()) {
        Some(&(field, _)) => Err(InvalidVelocity::NotFinite { field }),
        None => Ok(()),
    }
}

/// A body velocity whose every number is finite: what the mux commands and a driver plans its
/// motion frame from. Made by parsing ([`Velocity::new`], [`Velocity::twist`],
/// [`Velocity::steer`], [`ValidRequest::velocity`]) and changed only by operations that keep a
/// finite value finite ([`Velocity::bounded`], [`Velocity::towards`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Velocity(BodyVelocity);

impl Velocity {
    pub const ZERO: Velocity = Velocity(BodyVelocity::ZERO);

    /// Forward speed, lateral speed (omni robots), m/s, and yaw rate, rad/s.
    pub fn new(
        linear_x_mps: f32,
        linear_y_mps: f32,
        angular_z_radps: f32,
    ) -> Result<Self, InvalidVelocity> {
        finite(&[
            ("linear_x_mps", linear_x_mps),
            ("linear_y_mps", linear_y_mps),
            ("angular_z_radps", angular_z_radps),
        ])?;
        Ok(Self(BodyVelocity {
            linear_x_mps,
            linear_y_mps,
            angular_z_radps,
            ..BodyVelocity::ZERO
        }))
    }

    /// A twist (v, ω).
    pub fn twist(linear_x_mps: f32, angular_z_radps: f32) -> Result<Self, InvalidVelocity> {
        Self::new(linear_x_mps, 0.0, angular_z_radps)
    }

    /// A speed with a steering angle, rad, left positive (Ackermann robots).
    pub fn steer(linear_x_mps: f32, steer_rad: f32) -> Result<Self, InvalidVelocity> {
        finite(&[("linear_x_mps", linear_x_mps), ("steer_rad", steer_rad)])?;
        Ok(Self(BodyVelocity {
            linear_x_mps,
            steer_rad,
            flags: RequestFlags::STEER,
            ..BodyVelocity::ZERO
        }))
    }

    pub fn linear_x_mps(&self) -> f32 {
        self.0.linear_x_mps
    }

    pub fn linear_y_mps(&self) -> f32 {
        self.0.linear_y_mps
    }

    /// The yaw rate asked for; ignored when [`Velocity::uses_steer`].
    pub fn angular_z_radps(&self) -> f32 {
        self.0.angular_z_radps
    }

    /// The steering angle asked for; used only when [`Velocity::uses_steer`].
    pub fn steer_rad(&self) -> f32 {
        self.0.steer_rad
    }

    /// True when the velocity turns by a steering angle instead of a yaw rate.
    pub fn uses_steer(&self) -> bool {
        self.0.flags & RequestFlags::STEER != 0
    }

    /// True when it asks for no motion at all.
    pub fn is_zero(&self) -> bool {
        self.0.is_zero()
    }

    /// This velocity within `envelope`: the forward speed within
    /// `[-reverse_mps, forward_mps]`, the lateral speed and the yaw rate within ± their bounds.
    /// A bound only ever brings a speed towards zero (one on the far side of zero, or NaN,
    /// bounds nothing; an infinite one nothing either), so every result lies between zero and
    /// the speed it bounds: finite.
    pub fn bounded(self, envelope: &Envelope) -> Velocity {
        let within = |v: f32, lower: f32, upper: f32| {
            if v > upper && upper >= 0.0 {
                upper
            } else if v < lower && lower <= 0.0 {
                lower
            } else {
                v
            }
        };
        let (mut v, e) = (self.0, envelope);
        v.linear_x_mps = within(v.linear_x_mps, -e.reverse_mps, e.forward_mps);
        v.linear_y_mps = within(v.linear_y_mps, -e.lateral_mps, e.lateral_mps);
        v.angular_z_radps = within(v.angular_z_radps, -e.angular_radps, e.angular_radps);
        Velocity(v)
    }

    /// One step from this velocity towards `target`: each speed moves by at most `linear_step`
    /// (m/s) or `angular_step` (rad/s), and the steering angle is the target's. A negative or NaN
    /// step limits nothing. Every result lies between this velocity and the target: finite.
    /// The same motion slowed by `linear_step` m/s (a controlled stop's step): the yaw rate in
    /// proportion and the steering angle kept, so the robot keeps its path; zero once the
    /// step reaches the speed (a turn on the spot stops at once).
    pub fn braked(self, linear_step: f32) -> Velocity {
        let b = self.0;
        let speed = b.linear_x_mps.hypot(b.linear_y_mps);
        if speed <= linear_step || !linear_step.is_finite() {
            return Velocity::ZERO;
        }
        let k = (speed - linear_step) / speed;
        Velocity(BodyVelocity {
            linear_x_mps: b.linear_x_mps * k,
            linear_y_mps: b.linear_y_mps * k,
            angular_z_radps: b.angular_z_radps * k,
            ..b
        })
    }

    pub fn towards(self, target: Velocity, linear_step: f32, angular_step: f32) -> Velocity {
        let step = |from: f32, to: f32, max: f32| {
            let delta = to - from;
            if max >= 0.0 && delta.abs() > max {
                from + delta.signum() * max
            } else {
                to
            }
        };
        let (from, to) = (self.0, target.0);
        Velocity(BodyVelocity {
            linear_x_mps: step(from.linear_x_mps, to.linear_x_mps, linear_step),
            linear_y_mps: step(from.linear_y_mps, to.linear_y_mps, linear_step),
            angular_z_radps: step(from.angular_z_radps, to.angular_z_radps, angular_step),
            ..to
        })
    }
}

impl From<Velocity> for BodyVelocity {
    fn from(velocity: Velocity) -> Self {
        velocity.0
    }
}

/// Bounds on a velocity ([`Velocity::bounded`]), each 0 or more; an infinite one bounds
/// nothing.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Envelope {
    /// Largest forward speed, m/s.
    pub forward_mps: f32,
    /// Largest reverse speed, m/s.
    pub reverse_mps: f32,
    /// Largest |lateral speed|, m/s.
    pub lateral_mps: f32,
    /// Largest |yaw rate|, rad/s.
    pub angular_radps: f32,
}

impl Envelope {
    /// Bounds nothing ([`SafetyStatus::UNLIMITED`](crate::SafetyStatus::UNLIMITED) each way).
    pub const UNLIMITED: Envelope = Envelope {
        forward_mps: crate::SafetyStatus::UNLIMITED,
        reverse_mps: crate::SafetyStatus::UNLIMITED,
        lateral_mps: crate::SafetyStatus::UNLIMITED,
        angular_radps: crate::SafetyStatus::UNLIMITED,
    };
    /// Allows no motion.
    pub const ZERO: Envelope = Envelope {
        forward_mps: 0.0,
        reverse_mps: 0.0,
        lateral_mps: 0.0,
        angular_radps: 0.0,
    };

    /// The tighter of two envelopes, per direction.
    pub fn min(self, other: Envelope) -> Envelope {
        Envelope {
            forward_mps: self.forward_mps.min(other.forward_mps),
            reverse_mps: self.reverse_mps.min(other.reverse_mps),
            lateral_mps: self.lateral_mps.min(other.lateral_mps),
            angular_radps: self.angular_radps.min(other.angular_radps),
        }
    }
}

/// A [`VelocityRequest`] whose every number is finite and whose envelope, when it is a limit,
/// is not negative: what the mux takes. Made only by parsing (`ValidRequest::try_from`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ValidRequest(VelocityRequest);

/// A [`Velocity`] or a [`ValidRequest`] keeps its bytes in a snapshot of the state (bit for
/// bit), and is read back by parsing them again.
macro_rules! parsed_bytes {
    ($type:ty, $raw:ty, $parse:expr) => {
        impl Serialize for $type {
            fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                serializer.serialize_bytes(self.0.as_bytes())
            }
        }

        impl<'de> Deserialize<'de> for $type {
            fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
                let bytes: &[u8] = Deserialize::deserialize(deserializer)?;
                let raw = <$raw>::read_from_bytes(bytes)
                    .map_err(|_| D::Error::custom(concat!("not a ", stringify!($raw))))?;
                $parse(raw).map_err(D::Error::custom)
            }
        }
    };
}

parsed_bytes!(Velocity, BodyVelocity, |v: BodyVelocity| {
    finite(&[
        ("linear_x_mps", v.linear_x_mps),
        ("linear_y_mps", v.linear_y_mps),
        ("angular_z_radps", v.angular_z_radps),
        ("steer_rad", v.steer_rad),
    ])
    .map(|()| Velocity(v))
});
parsed_bytes!(ValidRequest, VelocityRequest, ValidRequest::try_from);

impl TryFrom<VelocityRequest> for ValidRequest {
    type Error = InvalidVelocity;

    /// Every number must be finite, even one the request does not use (a NaN anywhere is a
    /// client's bug); a limit's bounds must not be negative.
    fn try_from(request: VelocityRequest) -> Result<Self, InvalidVelocity> {
        let r = &request;
        let limits = [
            ("limit_forward_mps", r.limit_forward_mps),
            ("limit_reverse_mps", r.limit_reverse_mps),
            ("limit_lateral_mps", r.limit_lateral_mps),
            ("limit_angular_radps", r.limit_angular_radps),
        ];
        finite(&[
            ("linear_x_mps", r.linear_x_mps),
            ("linear_y_mps", r.linear_y_mps),
            ("angular_z_radps", r.angular_z_radps),
            ("steer_rad", r.steer_rad),
        ])?;
        finite(&limits)?;
        finite(&[("speed_limit_mps", r.speed_limit_mps)])?;
        if r.is_speed_limit() && r.speed_limit_mps <= 0.0 {
            return Err(InvalidVelocity::NonPositiveSpeedLimit);
        }
        if r.is_limit()
            && let Some(&(field, _)) = limits.iter().find(|(_, v)| *v < 0.0)
        {
            return Err(InvalidVelocity::NegativeLimit { field });
        }
        Ok(Self(request))
    }
}

/// A valid request reads as the request it was parsed from.
impl std::ops::Deref for ValidRequest {
    type Target = VelocityRequest;

    fn deref(&self) -> &VelocityRequest {
        &self.0
    }
}

impl ValidRequest {
    /// The same request stamped `stamp_ns` (`CLOCK_MONOTONIC`, ns): when it was made.
    pub fn with_stamp_ns(mut self, stamp_ns: u64) -> Self {
        self.0.stamp_ns = stamp_ns;
        self
    }

    /// The velocity it asks for (zero for a heartbeat or a limit).
    pub fn velocity(&self) -> Velocity {
        let r = &self.0;
        Velocity(BodyVelocity {
            linear_x_mps: r.linear_x_mps,
            linear_y_mps: r.linear_y_mps,
            angular_z_radps: r.angular_z_radps,
            steer_rad: r.steer_rad,
            flags: r.flags & RequestFlags::STEER,
        })
    }

    /// The speed limit it lowers the robot's to ([`RequestFlags::SPEED_LIMIT`]), m/s.
    pub fn speed_limit(&self) -> Option<f32> {
        self.0.is_speed_limit().then_some(self.0.speed_limit_mps)
    }

    /// The envelope of a limit ([`RequestFlags::LIMIT`]).
    pub fn envelope(&self) -> Option<Envelope> {
        let r = &self.0;
        r.is_limit().then_some(Envelope {
            forward_mps: r.limit_forward_mps,
            reverse_mps: r.limit_reverse_mps,
            lateral_mps: r.limit_lateral_mps,
            angular_radps: r.limit_angular_radps,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_braked_motion_keeps_its_path_and_ends_at_zero() {
        let v = Velocity::steer(1.0, 0.3).unwrap();
        let b = v.braked(0.25);
        assert_eq!(
            (b.linear_x_mps(), b.steer_rad(), b.uses_steer()),
            (0.75, 0.3, true)
        );
        let turn = Velocity::twist(0.5, 0.2).unwrap().braked(0.25);
        assert_eq!((turn.linear_x_mps(), turn.angular_z_radps()), (0.25, 0.1));
        assert!(
            v.braked(1.0).is_zero() && Velocity::twist(0.0, 0.5).unwrap().braked(0.1).is_zero()
        );
    }

    fn valid(request: VelocityRequest) -> Result<ValidRequest, InvalidVelocity> {
        ValidRequest::try_from(request)
    }

    #[test]
    fn a_request_with_a_nan_or_an_infinity_anywhere_is_refused_and_named() {
        assert!(valid(VelocityRequest::twist(0.3, -0.2)).is_ok());
        assert_eq!(
            valid(VelocityRequest::twist(f32::NAN, 0.0)),
            Err(InvalidVelocity::NotFinite {
                field: "linear_x_mps"
            })
        );
        assert_eq!(
            valid(VelocityRequest::steer(0.0, f32::INFINITY)),
            Err(InvalidVelocity::NotFinite { field: "steer_rad" })
        );
        // A NaN in a number the request does not use is refused too.
        let unused = VelocityRequest {
            limit_angular_radps: f32::NAN,
            ..VelocityRequest::twist(0.1, 0.0)
        };
        assert_eq!(
            valid(unused),
            Err(InvalidVelocity::NotFinite {
                field: "limit_angular_radps"
            })
        );
        let lateral = VelocityRequest {
            linear_y_mps: f32::NEG_INFINITY,
            ..VelocityRequest::default()
        };
        assert!(valid(lateral).is_err());
    }

    #[test]
    fn a_limit_is_alive_but_asks_for_nothing_and_must_not_be_negative() {
        let l = valid(VelocityRequest::limit(0.0, 0.5, 0.0, 1.0)).unwrap();
        assert!(l.is_heartbeat() && l.velocity().is_zero());
        assert_eq!(l.envelope().map(|e| e.reverse_mps), Some(0.5));
        assert_eq!(
            valid(VelocityRequest::limit(-0.1, 0.5, 0.0, 1.0)),
            Err(InvalidVelocity::NegativeLimit {
                field: "limit_forward_mps"
            })
        );
        assert!(valid(VelocityRequest::limit(f32::INFINITY, 0.5, 0.0, 1.0)).is_err());
        // Without the flag the bounds mean nothing, but must still be numbers.
        let not_a_limit = VelocityRequest {
            limit_forward_mps: -1.0,
            ..VelocityRequest::twist(0.1, 0.0)
        };
        assert!(valid(not_a_limit).is_ok_and(|r| r.envelope().is_none()));
    }

    #[test]
    fn a_speed_limit_is_a_positive_finite_number() {
        let l = valid(VelocityRequest::speed_limit(0.4)).unwrap();
        assert_eq!(l.speed_limit(), Some(0.4));
        assert!(valid(VelocityRequest::twist(0.4, 0.0)).is_ok_and(|r| r.speed_limit().is_none()));
        for bad in [0.0, -0.5] {
            assert_eq!(
                valid(VelocityRequest::speed_limit(bad)),
                Err(InvalidVelocity::NonPositiveSpeedLimit)
            );
        }
        assert_eq!(
            valid(VelocityRequest::speed_limit(f32::NAN)),
            Err(InvalidVelocity::NotFinite {
                field: "speed_limit_mps"
            })
        );
    }

    #[test]
    fn a_velocity_is_made_only_of_finite_numbers() {
        assert!(Velocity::twist(0.5, -0.1).is_ok());
        assert_eq!(
            Velocity::new(0.0, f32::NAN, 0.0),
            Err(InvalidVelocity::NotFinite {
                field: "linear_y_mps"
            })
        );
        assert!(Velocity::steer(f32::INFINITY, 0.1).is_err());
        let s = Velocity::steer(0.5, 0.2).unwrap();
        assert!(s.uses_steer() && !s.is_zero());
        assert_eq!(BodyVelocity::from(s).flags, RequestFlags::STEER);
        let r = valid(VelocityRequest::steer(0.5, 0.2)).unwrap();
        assert_eq!(r.velocity(), s);
    }

    #[test]
    fn a_bound_only_brings_a_speed_towards_zero() {
        let v = Velocity::new(0.8, -0.4, 1.5).unwrap();
        let e = Envelope {
            forward_mps: 0.5,
            reverse_mps: 0.0,
            lateral_mps: 0.1,
            angular_radps: 1.0,
        };
        assert_eq!(v.bounded(&e), Velocity::new(0.5, -0.1, 1.0).unwrap());
        let back = Velocity::twist(-0.3, 0.0).unwrap();
        assert_eq!(
            back.bounded(&e),
            Velocity::ZERO,
            "reverse 0 blocks reversing"
        );
        assert_eq!(v.bounded(&Envelope::UNLIMITED), v);
        // A NaN or negative bound bounds nothing; nothing comes out that is not finite.
        let odd = Envelope {
            forward_mps: f32::NAN,
            reverse_mps: -1.0,
            lateral_mps: f32::NEG_INFINITY,
            angular_radps: f32::NAN,
        };
        assert_eq!(v.bounded(&odd), v);
    }

    #[test]
    fn a_step_towards_a_target_moves_at_most_the_step_and_stays_between_the_two() {
        let from = Velocity::twist(0.0, 0.0).unwrap();
        let to = Velocity::new(1.0, -1.0, 2.0).unwrap();
        assert_eq!(
            from.towards(to, 0.25, 0.5),
            Velocity::new(0.25, -0.25, 0.5).unwrap()
        );
        assert_eq!(from.towards(to, f32::INFINITY, f32::INFINITY), to);
        assert_eq!(from.towards(to, f32::NAN, -1.0), to, "no step: no limit");
        let far = Velocity::twist(f32::MAX, 0.0).unwrap();
        let near = Velocity::twist(-f32::MAX, 0.0).unwrap();
        let stepped = far.towards(near, f32::MAX, 0.0);
        assert!(stepped.linear_x_mps().is_finite());
        let steer = Velocity::steer(0.5, 0.3).unwrap();
        assert!(from.towards(steer, 0.1, 0.1).uses_steer());
    }
}
