//! The path follower: pure pursuit on the odometry pose with a speed profile, for robots that
//! turn on the spot and robots that steer. A plain struct without a clock: each
//! [`Tracker::update`] takes the measured pose and speeds and the time since the previous call,
//! and answers the command to send.
//!
//! # How it drives
//!
//! * **Stops.** The path's end is a stop; for a robot that turns on the spot so is every corner
//!   sharper than [`TrackerConfig::corner_angle_rad`]. The robot drives each leg to its stop,
//!   turns on the spot to the next leg's heading and drives on. Between stops the projection of
//!   the robot on the path is searched in a window ahead of its progress that never passes the
//!   next stop, so a path that crosses or closes on itself is followed in order.
//! * **Steering: pure pursuit.** The lookahead point lies `L = L₀ + k·|v|` (clamped) ahead of the
//!   robot's projection; past a stop it lies on the straight continuation of the leg ending
//!   there, so the approach stays straight. The curvature to reach it is κ = 2·y / d² (y its
//!   lateral offset, d its distance in the robot's frame), limited to 1 / the minimum turning
//!   radius for a steered robot (a point behind it asks for the tightest turn toward it). The
//!   command is the twist (v, κ·v): the robot's driver turns it into a steering angle (TITAN)
//!   or wheel speeds. A robot that turns on the spot and finds the lookahead point more than
//!   [`TrackerConfig::realign_angle_rad`] off its heading (after a preemption moved it, say)
//!   turns on the spot toward it first.
//! * **Speed.** The cruise speed, limited by the path's curvature (lateral acceleration, the
//!   robot's yaw-rate limit), by braking at
//!   [`TrackerConfig::decel_mps2`] toward the next stop, and raised at most at
//!   [`TrackerConfig::accel_mps2`]. Near a stop a proportional controller on the along-track
//!   distance takes over, never slower than the robot's slowest useful speed; the robot is
//!   told to stop once the distance left is what it will coast (speed × its response lag).
//! * **Goal.** At the end the robot stops; once it stands still the goal is reached when it is
//!   within the tolerance of the last point. If not, a robot that moves sideways (omni wheels)
//!   drives straight to it without turning; a robot that turns on the spot turns toward the goal
//!   (or away from it, to back up) and drives straight to it; a steered robot only drives
//!   straight forward or back, so a sideways miss is a failure. Three tries at most.

use thiserror::Error;

use crate::geometry::{Point, Pose, wrap_angle};
use crate::kinematics::{Kinematics, Steering};
use crate::path::Path;

/// How many corrections at the goal before giving up.
pub const MAX_CORRECTIONS: u32 = 3;

/// Speed below which the robot counts as standing still, m/s.
const STANDSTILL_MPS: f64 = 0.01;
/// Yaw rate below which the robot counts as not turning, rad/s.
const STANDSTILL_RADPS: f64 = 0.02;
/// A stop is reached when the robot will coast to within this of it, m.
const ARRIVE_M: f64 = 0.005;
/// The projection may move back this far (a robot pushed back), m.
const BACK_WINDOW_M: f64 = 0.3;
/// Top speed of a correction at the goal, m/s.
const CORRECTION_MPS: f64 = 0.2;

/// The follower's tuning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerConfig {
    pub kinematics: Kinematics,
    /// Speed on straight legs, m/s.
    pub cruise_mps: f64,
    /// Largest increase of the commanded speed, m/s².
    pub accel_mps2: f64,
    /// Braking toward a stop, m/s².
    pub decel_mps2: f64,
    /// Largest lateral acceleration on a curve, m/s².
    pub lateral_accel_mps2: f64,
    /// Goal reached within this distance of the last point, m.
    pub goal_tolerance_m: f64,
    /// Lookahead L₀, m.
    pub lookahead_min_m: f64,
    /// Lookahead growth with speed, s.
    pub lookahead_gain_s: f64,
    /// Largest lookahead, m.
    pub lookahead_max_m: f64,
    /// Gain of the final approach on the along-track distance, 1/s.
    pub approach_gain: f64,
    /// A corner turning more than this is a stop with a turn on the spot (robots that can), rad.
    pub corner_angle_rad: f64,
    /// Gain of a turn on the spot, 1/s.
    pub turn_gain: f64,
    /// A turn on the spot ends within this of its heading, rad.
    pub turn_tolerance_rad: f64,
    /// While driving, a robot that turns on the spot does so when the lookahead point is more
    /// than this off its heading, rad.
    pub realign_angle_rad: f64,
    /// Driving a closed loop forever: the path holds three loops, and progress moves back by
    /// this (one loop, m) whenever it reaches two.
    pub period_m: Option<f64>,
}

impl TrackerConfig {
    /// The defaults for `kinematics` at `cruise_mps`.
    pub fn new(kinematics: Kinematics, cruise_mps: f64) -> Self {
        let steered = !kinematics.turns_on_the_spot();
        Self {
            kinematics,
            cruise_mps,
            accel_mps2: 0.8,
            decel_mps2: 0.6,
            lateral_accel_mps2: 0.6,
            goal_tolerance_m: 0.05,
            lookahead_min_m: if steered { 0.4 } else { 0.25 },
            lookahead_gain_s: if steered { 0.4 } else { 0.3 },
            lookahead_max_m: if steered { 2.0 } else { 1.5 },
            approach_gain: 2.5,
            corner_angle_rad: 0.35,
            turn_gain: 2.0,
            turn_tolerance_rad: 0.03,
            realign_angle_rad: 0.8,
            period_m: None,
        }
    }

    fn lookahead_m(&self, speed_mps: f64) -> f64 {
        (self.lookahead_min_m + self.lookahead_gain_s * speed_mps.abs())
            .clamp(self.lookahead_min_m, self.lookahead_max_m)
    }
}

/// What the robot measures: its pose and speeds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measured {
    pub pose: Pose,
    pub linear_mps: f64,
    pub angular_radps: f64,
    /// Sideways speed, left positive (robots that move sideways), m/s.
    pub lateral_mps: f64,
}

/// A twist to send.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Command {
    pub linear_mps: f64,
    pub angular_radps: f64,
    /// Sideways speed, left positive: only for a robot that moves sideways, m/s.
    pub lateral_mps: f64,
}

impl Command {
    pub const STOP: Command = Command {
        linear_mps: 0.0,
        angular_radps: 0.0,
        lateral_mps: 0.0,
    };
}

/// What the follower is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activity {
    /// Turning on the spot (at the start, at a corner, to realign).
    Turning,
    /// Following the path.
    Driving,
    /// Stopped or stopping at the goal, waiting for the robot to stand still.
    Stopping,
    /// Correcting a miss of the goal.
    Correcting,
    /// At the goal, standing still.
    Done,
}

impl Activity {
    pub fn name(self) -> &'static str {
        match self {
            Activity::Turning => "turning",
            Activity::Driving => "driving",
            Activity::Stopping => "stopping",
            Activity::Correcting => "correcting",
            Activity::Done => "done",
        }
    }
}

/// One step's answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    pub command: Command,
    pub activity: Activity,
    /// Progress along the path, m (within the current loop when repeating).
    pub progress_m: f64,
    /// Path left to drive, m (`None` when repeating forever).
    pub remaining_m: Option<f64>,
    /// Signed distance from the path, m (left positive).
    pub cross_track_m: f64,
    /// Distance to the last point, m.
    pub goal_distance_m: f64,
    /// Loops completed when repeating forever.
    pub laps: u64,
}

/// Why the follower gives up.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrackError {
    #[error(
        "stopped {distance_m:.3} m from the goal, {lateral_m:.3} m to the side (tolerance \
         {tolerance_m} m): a robot that cannot turn on the spot cannot correct that"
    )]
    SidewaysMiss {
        distance_m: f64,
        lateral_m: f64,
        tolerance_m: f64,
    },
    #[error(
        "still {distance_m:.3} m from the goal after {MAX_CORRECTIONS} corrections (tolerance \
         {tolerance_m} m)"
    )]
    CannotSettle { distance_m: f64, tolerance_m: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Turning { target_yaw: f64 },
    Driving,
    Stopping,
    Correcting { turned: bool },
    Done,
}

/// The path follower.
#[derive(Debug, Clone)]
pub struct Tracker {
    config: TrackerConfig,
    path: Path,
    /// Arc lengths where the robot must stand still (sharp corners, the end), ascending.
    stops: Vec<f64>,
    /// Index into `stops` of the next one.
    next_stop: usize,
    /// Speed limit at each path point, after braking toward the stops.
    vertex_limit: Vec<f64>,
    /// Speed limit of each segment from its curvature (stops not counted).
    segment_limit: Vec<f64>,
    phase: Phase,
    /// Progress, m.
    s: f64,
    /// The projection never goes back past this (the last stop passed), m.
    floor_s: f64,
    last_speed: f64,
    corrections: u32,
    laps: u64,
    started: bool,
}

impl Tracker {
    /// A follower of `path` (already in the pose's frame: the odometry frame).
    pub fn new(path: Path, config: TrackerConfig) -> Self {
        let kin = config.kinematics;
        let angles = path.turn_angles();
        let s = path.arc_lengths().to_vec();
        let n = s.len();
        let mut stops = Vec::new();
        if kin.turns_on_the_spot() {
            for (i, angle) in angles.iter().enumerate().take(n - 1).skip(1) {
                if angle.abs() > config.corner_angle_rad {
                    stops.push(s[i]);
                }
            }
        }
        stops.push(path.length_m());
        let (vertex_limit, segment_limit) = speed_profile(&config, &path, &stops);
        Self {
            config,
            path,
            stops,
            next_stop: 0,
            vertex_limit,
            segment_limit,
            phase: Phase::Driving,
            s: 0.0,
            floor_s: 0.0,
            last_speed: 0.0,
            corrections: 0,
            laps: 0,
            started: false,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// Drives on within new limits (a newer description of the robot): the speed profile is
    /// made again, the progress kept. The path stays what it was built for, so `kinematics`
    /// must turn the same way, no wider ([`Kinematics::updated_by`] makes such limits).
    pub fn set_kinematics(&mut self, kinematics: Kinematics) {
        self.config.kinematics = kinematics;
        let (vertex_limit, segment_limit) = speed_profile(&self.config, &self.path, &self.stops);
        self.vertex_limit = vertex_limit;
        self.segment_limit = segment_limit;
        self.last_speed = self.last_speed.min(kinematics.max_linear_mps);
    }

    /// The arc lengths where the robot stops (sharp corners and the end).
    pub fn stops(&self) -> &[f64] {
        &self.stops
    }

    /// Turns on the spot at corners: on the whole path, or in one loop when repeating forever.
    pub fn corner_stops(&self) -> usize {
        match self.config.period_m {
            Some(period) if period > 0.0 => self
                .stops
                .iter()
                .filter(|&&s| s >= period - 1e-6 && s < 2.0 * period - 1e-6)
                .count(),
            _ => self.stops.len().saturating_sub(1),
        }
    }

    /// The last point of the path.
    pub fn goal(&self) -> Point {
        self.path.end()
    }

    /// The robot is held (another source won the mux): the next speed-up starts from what it
    /// does now, not from what was asked while nobody listened.
    pub fn hold(&mut self, measured: &Measured) {
        self.last_speed = measured.linear_mps.abs();
    }

    /// The command for the robot as measured, `dt_s` after the previous call.
    pub fn update(&mut self, m: &Measured, dt_s: f64) -> Result<Step, TrackError> {
        let dt_s = if dt_s.is_finite() {
            dt_s.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let finite = [
            m.pose.x,
            m.pose.y,
            m.pose.yaw,
            m.linear_mps,
            m.angular_radps,
            m.lateral_mps,
        ]
        .iter()
        .all(|v| v.is_finite());
        if !finite {
            // Nothing to steer by: stand still and keep the progress.
            self.last_speed = 0.0;
            return Ok(Step {
                command: Command::STOP,
                activity: self.activity(),
                progress_m: self.s,
                remaining_m: self
                    .config
                    .period_m
                    .is_none()
                    .then(|| (self.path.length_m() - self.s).max(0.0)),
                cross_track_m: 0.0,
                goal_distance_m: f64::NAN,
                laps: self.laps,
            });
        }
        if !self.started {
            self.started = true;
            self.s = 0.0;
            let heading = self.path.heading_after(0.0);
            if self.config.kinematics.turns_on_the_spot()
                && wrap_angle(heading - m.pose.yaw).abs() > self.config.turn_tolerance_rad * 3.0
            {
                self.phase = Phase::Turning {
                    target_yaw: heading,
                };
            }
        }
        let mut command = Command::STOP;
        let mut cross_track = 0.0;
        // A phase change is acted on in the same step (at most a few).
        for _ in 0..4 {
            match self.phase {
                Phase::Turning { target_yaw } => match self.turn(m, target_yaw) {
                    Some(c) => {
                        command = c;
                        break;
                    }
                    None => self.phase = Phase::Driving,
                },
                Phase::Driving => {
                    let (c, lateral) = self.drive(m, dt_s);
                    cross_track = lateral;
                    if let Some(c) = c {
                        command = c;
                        break;
                    }
                }
                Phase::Stopping => {
                    command = Command::STOP;
                    if m.linear_mps.abs() < STANDSTILL_MPS
                        && m.angular_radps.abs() < STANDSTILL_RADPS
                    {
                        let distance = m.pose.position().distance(self.goal());
                        if distance <= self.config.goal_tolerance_m {
                            self.phase = Phase::Done;
                        } else if self.corrections >= MAX_CORRECTIONS {
                            return Err(TrackError::CannotSettle {
                                distance_m: distance,
                                tolerance_m: self.config.goal_tolerance_m,
                            });
                        } else {
                            self.corrections += 1;
                            self.phase = Phase::Correcting { turned: false };
                            continue;
                        }
                    }
                    break;
                }
                Phase::Correcting { turned } => {
                    match self.correct(m, turned)? {
                        Some(c) => command = c,
                        None => {
                            self.phase = Phase::Stopping;
                            command = Command::STOP;
                        }
                    }
                    break;
                }
                Phase::Done => {
                    command = Command::STOP;
                    break;
                }
            }
        }
        if !matches!(self.phase, Phase::Driving) {
            self.last_speed = command.linear_mps.abs();
        }
        let length = self.path.length_m();
        let remaining = match self.config.period_m {
            Some(_) => None,
            None => Some((length - self.s).max(0.0)),
        };
        let (progress, laps) = match self.config.period_m {
            Some(period) if period > 0.0 => {
                let s = self.s.max(0.0);
                // Whole loops in `s`: small, positive and finite.
                (s % period, self.laps + (s / period).floor() as u64)
            }
            _ => (self.s.clamp(0.0, length), 0),
        };
        Ok(Step {
            command,
            activity: self.activity(),
            progress_m: progress,
            remaining_m: remaining,
            cross_track_m: cross_track,
            goal_distance_m: m.pose.position().distance(self.goal()),
            laps,
        })
    }

    fn activity(&self) -> Activity {
        match self.phase {
            Phase::Turning { .. } => Activity::Turning,
            Phase::Driving => Activity::Driving,
            Phase::Stopping => Activity::Stopping,
            Phase::Correcting { .. } => Activity::Correcting,
            Phase::Done => Activity::Done,
        }
    }

    /// A turn on the spot toward `target_yaw`; `None` once it will end there.
    fn turn(&self, m: &Measured, target_yaw: f64) -> Option<Command> {
        let c = &self.config;
        let error = wrap_angle(target_yaw - m.pose.yaw);
        let coast = m.angular_radps * c.kinematics.response_lag_s;
        if (error - coast).abs() <= c.turn_tolerance_rad || error.abs() <= c.turn_tolerance_rad {
            return None;
        }
        let max = c.kinematics.max_angular_radps();
        let rate = (c.turn_gain * error.abs()).clamp(c.kinematics.min_angular_radps, max);
        Some(Command {
            angular_radps: error.signum() * rate,
            ..Command::STOP
        })
    }

    /// Speed limit of the profile at arc length `s`.
    fn profile_speed(&self, s: f64) -> f64 {
        let arcs = self.path.arc_lengths();
        let n = arcs.len();
        let j = arcs.partition_point(|&x| x <= s).clamp(1, n - 1);
        let i = j - 1;
        let braking = (self.vertex_limit[j].powi(2)
            + 2.0 * self.config.decel_mps2 * (arcs[j] - s).max(0.0))
        .sqrt();
        self.segment_limit[i].min(braking)
    }

    /// One step along the path: the command (`None` after a phase change) and the cross-track
    /// error.
    fn drive(&mut self, m: &Measured, dt_s: f64) -> (Option<Command>, f64) {
        let c = self.config;
        let kin = c.kinematics;
        let position = m.pose.position();
        let stop = self.stops[self.next_stop.min(self.stops.len() - 1)];
        let lookahead = c.lookahead_m(m.linear_mps);
        let window = (2.0 * c.lookahead_max_m).max(1.0);
        let from = (self.s - BACK_WINDOW_M).max(self.floor_s);
        let to = (self.s + window).min(stop);
        let projection = self.path.project(position, from, to, to >= stop);
        self.s = projection.s;
        if let Some(period) = c.period_m
            && period > 0.0
            && self.s >= 2.0 * period
        {
            self.rebase(period);
            return (None, projection.lateral_m);
        }
        let lateral = projection.lateral_m;
        let along = stop - self.s;
        let coast = m.linear_mps * kin.response_lag_s;
        let left = along - coast;
        if left <= ARRIVE_M {
            let is_end = self.next_stop + 1 >= self.stops.len();
            if is_end {
                self.phase = Phase::Stopping;
            } else {
                self.floor_s = stop;
                self.s = self.s.max(stop);
                self.next_stop += 1;
                let heading = self.path.heading_after(stop);
                self.phase = Phase::Turning {
                    target_yaw: heading,
                };
            }
            return (None, lateral);
        }
        let target = self
            .path
            .point_at_until(self.s + lookahead, stop.max(self.s));
        let local = m.pose.to_local(target);
        let bearing = local.y.atan2(local.x);
        if kin.turns_on_the_spot() && bearing.abs() > c.realign_angle_rad {
            self.phase = Phase::Turning {
                target_yaw: m.pose.yaw + bearing,
            };
            return (None, lateral);
        }
        let d2 = local.x * local.x + local.y * local.y;
        let mut curvature = if d2 > 1e-12 { 2.0 * local.y / d2 } else { 0.0 };
        if let Steering::Ackermann { .. } = kin.steering {
            let max = kin.max_curvature();
            if local.x <= 0.0 {
                curvature = if local.y < 0.0 { -max } else { max };
            }
            curvature = curvature.clamp(-max, max);
        }
        let mut speed = self
            .profile_speed(self.s)
            .min(curve_speed(&c, curvature))
            .min((c.approach_gain * left).max(0.0))
            .min((2.0 * c.decel_mps2 * left.max(0.0)).sqrt())
            .max(kin.min_linear_mps);
        speed = speed.min(self.last_speed + c.accel_mps2 * dt_s);
        speed = speed.min(kin.max_linear_mps);
        let mut angular = curvature * speed;
        let max_angular = kin.max_angular_radps();
        if angular.abs() > max_angular {
            angular = angular.signum() * max_angular;
            speed = max_angular / curvature.abs();
        }
        self.last_speed = speed;
        (
            Some(Command {
                linear_mps: speed,
                angular_radps: angular,
                lateral_mps: 0.0,
            }),
            lateral,
        )
    }

    /// Moves progress back one loop (repeating forever).
    fn rebase(&mut self, period: f64) {
        let target = self.stops[self.next_stop.min(self.stops.len() - 1)] - period;
        self.s -= period;
        self.floor_s = (self.floor_s - period).max(0.0);
        self.next_stop = self
            .stops
            .iter()
            .position(|&x| x >= target - 1e-6)
            .unwrap_or(0);
        self.laps += 1;
    }

    /// A straight correction toward the goal: `None` once the robot will stop there.
    fn correct(&mut self, m: &Measured, turned: bool) -> Result<Option<Command>, TrackError> {
        let c = self.config;
        let kin = c.kinematics;
        let goal = m.pose.to_local(self.goal());
        let distance = goal.x.hypot(goal.y);
        let slowest = kin.min_linear_mps;
        let fastest = |reverse: bool| {
            let limit = if reverse {
                kin.max_reverse_mps
            } else {
                kin.max_linear_mps
            };
            CORRECTION_MPS.min(limit).max(slowest)
        };
        if kin.lateral_mps > 0.0 {
            // Straight at the goal, forward and sideways at once, without turning.
            let left = (
                goal.x - m.linear_mps * kin.response_lag_s,
                goal.y - m.lateral_mps * kin.response_lag_s,
            );
            let length = left.0.hypot(left.1);
            if length <= ARRIVE_M {
                return Ok(None);
            }
            let top = fastest(left.0 < 0.0).min(kin.lateral_mps.max(slowest));
            let speed = (c.approach_gain * length).clamp(slowest, top);
            return Ok(Some(Command {
                linear_mps: speed * left.0 / length,
                lateral_mps: speed * left.1 / length,
                ..Command::STOP
            }));
        }
        if kin.turns_on_the_spot() {
            let bearing = goal.y.atan2(goal.x);
            let facing = if bearing.abs() > std::f64::consts::FRAC_PI_2 {
                wrap_angle(bearing - std::f64::consts::PI)
            } else {
                bearing
            };
            if !turned {
                let target_yaw = m.pose.yaw + facing;
                if let Some(command) = self.turn(m, target_yaw) {
                    return Ok(Some(command));
                }
                self.phase = Phase::Correcting { turned: true };
            }
        } else if goal.y.abs() > 0.8 * c.goal_tolerance_m {
            return Err(TrackError::SidewaysMiss {
                distance_m: distance,
                lateral_m: goal.y,
                tolerance_m: c.goal_tolerance_m,
            });
        }
        let left = goal.x - m.linear_mps * kin.response_lag_s;
        if left.abs() <= ARRIVE_M {
            return Ok(None);
        }
        let speed = (c.approach_gain * left.abs()).clamp(slowest, fastest(left < 0.0));
        Ok(Some(Command {
            linear_mps: left.signum() * speed,
            ..Command::STOP
        }))
    }
}

/// Top speed on curvature `k` (1/m): lateral acceleration and the robot's limits, with a fifth
/// of a differential robot's yaw rate kept for corrections.
fn curve_speed(config: &TrackerConfig, k: f64) -> f64 {
    let k = k.abs();
    let lateral = if k > 1e-9 {
        (config.lateral_accel_mps2 / k).sqrt()
    } else {
        f64::INFINITY
    };
    let robot = match config.kinematics.steering {
        Steering::Differential => config.kinematics.max_speed_at(k / 0.8),
        Steering::Ackermann { .. } => config.kinematics.max_speed_at(k),
    };
    lateral.min(robot).min(config.cruise_mps)
}

/// The speed limit at each point of `path` (braking toward the stops included) and of each of
/// its segments (from the curvature pure pursuit will ask for around its ends), within the
/// cruise speed and the robot's limits.
fn speed_profile(config: &TrackerConfig, path: &Path, stops: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let angles = path.turn_angles();
    let s = path.arc_lengths();
    let n = s.len();
    let cruise = config.cruise_mps.min(config.kinematics.max_linear_mps);
    let nominal_lookahead = config.lookahead_m(cruise);
    // The curvature pure pursuit will ask for around each point.
    let mut raw = vec![cruise; n];
    for i in 1..n - 1 {
        let span = (0.5 * (s[i + 1] - s[i - 1])).min(nominal_lookahead);
        let k = if span > 0.0 {
            angles[i].abs() / span
        } else {
            0.0
        };
        raw[i] = curve_speed(config, k).min(cruise);
    }
    let is_stop = |i: usize| stops.iter().any(|&x| (x - s[i]).abs() < 1e-9);
    let segment_limit: Vec<f64> = (0..n - 1)
        .map(|i| {
            let a = if is_stop(i) { cruise } else { raw[i] };
            let b = if is_stop(i + 1) { cruise } else { raw[i + 1] };
            a.min(b)
        })
        .collect();
    let mut vertex_limit: Vec<f64> = (0..n)
        .map(|i| if is_stop(i) { 0.0 } else { raw[i] })
        .collect();
    for i in (0..n - 1).rev() {
        let reachable =
            (vertex_limit[i + 1].powi(2) + 2.0 * config.decel_mps2 * (s[i + 1] - s[i])).sqrt();
        vertex_limit[i] = vertex_limit[i].min(reachable);
    }
    (vertex_limit, segment_limit)
}

#[cfg(test)]
mod tests;
