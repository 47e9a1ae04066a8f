//! `VelocityRequest`: what a client asks the mux for, on its own `cmd/<source>` service.

use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

use crate::layout::ipc_type;
use crate::named::named_constants;

named_constants! {
    /// Bits of [`VelocityRequest::flags`] (and of `BodyVelocity::flags`).
    pub flags RequestFlags: u32 {
        /// `steer_rad` holds the steering angle to use (Ackermann robots); `angular_z_radps` is
        /// ignored.
        STEER = 1 << 0 => "steer",
        /// A heartbeat: the source is alive but asks for nothing (it does not compete in the
        /// mux). The safety monitor sends these while all is well.
        HEARTBEAT = 1 << 1 => "heartbeat",
        /// The `limit_*` fields hold a speed envelope: the source does not compete, but clamps
        /// the output of every source of its priority or lower, per direction (the safety
        /// monitor slowing down, or blocking only the motion towards an obstacle). Implies a
        /// heartbeat.
        LIMIT = 1 << 2 => "limit",
        /// The request only lowers the robot's standing speed limit to `speed_limit_mps` (> 0):
        /// it asks nothing else and leaves the source's latest request as it was. The limit caps
        /// every source until the operator raises it (`ControlKind::SPEED_LIMIT`); a larger value
        /// from a source changes nothing.
        SPEED_LIMIT = 1 << 3 => "speed_limit",
        /// The locks this request engages stop with `StopCategory::CUT` instead of their
        /// configured category (the lowest of the category bits set wins).
        CATEGORY_0 = 1 << 4 => "category_0",
        /// … with `StopCategory::BRAKE_THEN_CUT`.
        CATEGORY_1 = 1 << 5 => "category_1",
        /// … with `StopCategory::HOLD`.
        CATEGORY_2 = 1 << 6 => "category_2",
    }
}

impl RequestFlags {
    /// The stop category a request's category bits ask for, if any (the lowest set).
    pub fn category(flags: u32) -> Option<u8> {
        [Self::CATEGORY_0, Self::CATEGORY_1, Self::CATEGORY_2]
            .iter()
            .position(|&bit| flags & bit != 0)
            .and_then(|c| u8::try_from(c).ok())
    }

    /// The category bit of `category` (0 for none or an unknown one).
    pub fn of_category(category: u8) -> u32 {
        match category {
            0 => Self::CATEGORY_0,
            1 => Self::CATEGORY_1,
            2 => Self::CATEGORY_2,
            _ => 0,
        }
    }
}

ipc_type! {
    /// A velocity request from one source. Its priority and timeout come from the service's
    /// configuration, never from the request. Plain bytes that may hold anything: where one
    /// enters a process it is parsed into a [`crate::ValidRequest`].
    #[derive(Default, Serialize)]
    #[type_name("chassis::VelocityRequest.v3")]
    pub struct VelocityRequest {
        /// `CLOCK_MONOTONIC` time the request was created, ns.
        pub stamp_ns: u64,
        /// Incremented by the client for every request.
        pub seq: u64,
        /// Forward speed, m/s.
        pub linear_x_mps: f32,
        /// Lateral speed, m/s, left positive (omni robots only).
        pub linear_y_mps: f32,
        /// Yaw rate, rad/s, left turn positive.
        pub angular_z_radps: f32,
        /// Steering angle, rad, left turn positive; used when `flags` has [`RequestFlags::STEER`].
        pub steer_rad: f32,
        /// [`RequestFlags`].
        pub flags: u32,
        /// Lock bits this source engages (bit i = lock i of the mux's configuration, as listed in
        /// `MuxStatus::locks`).
        pub lock_engage: u32,
        /// Lock bits this source releases (only locks it holds itself).
        pub lock_release: u32,
        /// With [`RequestFlags::SPEED_LIMIT`]: the largest linear speed, m/s (> 0), for every
        /// source from now on.
        pub speed_limit_mps: f32,
        /// With [`RequestFlags::LIMIT`]: largest forward speed, m/s (≥ 0; 0 blocks forward motion).
        pub limit_forward_mps: f32,
        /// With [`RequestFlags::LIMIT`]: largest reverse speed, m/s (≥ 0; 0 blocks reversing).
        pub limit_reverse_mps: f32,
        /// With [`RequestFlags::LIMIT`]: largest |lateral speed|, m/s (≥ 0).
        pub limit_lateral_mps: f32,
        /// With [`RequestFlags::LIMIT`]: largest |yaw rate|, rad/s (≥ 0).
        pub limit_angular_radps: f32,
    }
}

impl VelocityRequest {
    /// A twist request (v, ω).
    pub fn twist(linear_x_mps: f32, angular_z_radps: f32) -> Self {
        Self {
            linear_x_mps,
            angular_z_radps,
            ..Self::default()
        }
    }

    /// A speed with a steering angle (Ackermann robots).
    pub fn steer(linear_x_mps: f32, steer_rad: f32) -> Self {
        Self {
            linear_x_mps,
            steer_rad,
            flags: RequestFlags::STEER,
            ..Self::default()
        }
    }

    /// A speed envelope imposed on every source of this source's priority or lower.
    pub fn limit(forward_mps: f32, reverse_mps: f32, lateral_mps: f32, angular_radps: f32) -> Self {
        Self {
            flags: RequestFlags::LIMIT,
            limit_forward_mps: forward_mps,
            limit_reverse_mps: reverse_mps,
            limit_lateral_mps: lateral_mps,
            limit_angular_radps: angular_radps,
            ..Self::default()
        }
    }

    /// Lowers the robot's standing speed limit to `mps` (> 0) for every source.
    pub fn speed_limit(mps: f32) -> Self {
        Self {
            flags: RequestFlags::SPEED_LIMIT,
            speed_limit_mps: mps,
            ..Self::default()
        }
    }

    /// A heartbeat that asks for nothing.
    pub fn heartbeat() -> Self {
        Self {
            flags: RequestFlags::HEARTBEAT,
            ..Self::default()
        }
    }

    /// True when the request asks for no motion of its own (a heartbeat or a limit).
    pub fn is_heartbeat(&self) -> bool {
        self.flags & (RequestFlags::HEARTBEAT | RequestFlags::LIMIT) != 0
    }

    pub fn is_limit(&self) -> bool {
        self.flags & RequestFlags::LIMIT != 0
    }

    pub fn is_speed_limit(&self) -> bool {
        self.flags & RequestFlags::SPEED_LIMIT != 0
    }

    pub fn uses_steer(&self) -> bool {
        self.flags & RequestFlags::STEER != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_set_their_flags() {
        assert!(VelocityRequest::heartbeat().is_heartbeat());
        assert!(VelocityRequest::steer(1.0, 0.1).uses_steer());
        assert!(!VelocityRequest::twist(1.0, 0.1).uses_steer());
    }
}
