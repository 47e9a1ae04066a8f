//! The XBot's profile: its physical constants and the ⚠ choices of its manual.

use serde::{Deserialize, Serialize};

/// XBot: differential (optionally omni) drive, RS232, little-endian.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct XbotProfile {
    /// Baud rate of the control link (not in the manual), 8N1.
    pub baud: u32,
    /// Baud rate of the GPS receiver's NMEA stream, 8N1.
    pub gps_baud: u32,
    /// Drive wheel diameter, m.
    pub wheel_diameter_m: f64,
    /// ⚠ Encoder counts per wheel turn: the protocol note says 8000; the spec sheet's 1000-line
    /// encoder behind 1:16 and "0.019 mm per count" disagree.
    pub encoder_counts_per_rev: f64,
    /// Distance between the drive wheels, m. Not in the manual: odometry from the encoders is
    /// only published once this is set.
    pub wheel_separation_m: Option<f64>,
    /// Top speed, m/s.
    pub max_linear_mps: f64,
    /// Smallest speed the board executes, m/s (smaller requests are sent as 0).
    pub min_linear_mps: f64,
    /// Largest yaw rate the driver will command, rad/s.
    pub max_angular_rad_s: f64,
    /// True for omni variants that accept a lateral speed.
    pub omni: bool,
    /// ⚠ Yaw-rate sign on the wire. Note 1 says positive is a left turn (default); the examples
    /// label +20 °/s "turn right".
    pub yaw_rate_left_positive: bool,
    /// ⚠ Lateral-speed sign on the wire. The examples label +vy "move right" (default false).
    pub lateral_left_positive: bool,
    /// ⚠ Decode motor currents and ultrasonic ranges as BCD (the vendor's 2017 driver) instead
    /// of plain binary (the manual, default).
    pub bcd_currents_and_ranges: bool,
    /// Heartbeat (0x03) rate, Hz: the manual wants more than 5 and less than 10.
    pub heartbeat_hz: f64,
    /// The board's command timeout, ms.
    pub command_timeout_ms: u64,
    /// Battery voltage when fully charged, V (the manual's charging voltage, 24.9 V).
    pub battery_full_v: f64,
    /// Battery voltage below which the robot should be charged, V. Not in the manual: 15 % of
    /// the 23.0-26.0 V range the simulated chassis models; set your pack's level.
    pub battery_low_v: f64,
}

impl Default for XbotProfile {
    fn default() -> Self {
        Self {
            baud: 115_200,
            gps_baud: 4800,
            wheel_diameter_m: 0.2,
            encoder_counts_per_rev: 8000.0,
            wheel_separation_m: None,
            max_linear_mps: 1.5,
            min_linear_mps: 0.01,
            max_angular_rad_s: std::f64::consts::PI,
            omni: false,
            yaw_rate_left_positive: true,
            lateral_left_positive: false,
            bcd_currents_and_ranges: false,
            heartbeat_hz: 8.0,
            command_timeout_ms: 500,
            battery_full_v: 24.9,
            battery_low_v: 23.45,
        }
    }
}

impl XbotProfile {
    /// Wheel travel per encoder count, m.
    pub fn metres_per_count(&self) -> f64 {
        std::f64::consts::PI * self.wheel_diameter_m / self.encoder_counts_per_rev
    }
}
