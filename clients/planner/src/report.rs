//! What the planner prints on stdout: a start line, a progress line every second, events
//! (preempted, resumed), and a summary — as text, or with `--json` as one JSON object a line
//! with an `event` field (`start`, `progress`, `preempted`, `resumed`, `goal`, `failed`,
//! `interrupted`). Errors also go to stderr as text either way.

use std::io::Write;

use serde_json::{Value, json};

use crate::geometry::Pose;
use crate::kinematics::Kinematics;

/// Where the plan starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Start {
    pub robot: String,
    /// What the robot is, from its description (`AgileX TITAN (titan)`).
    pub described_as: String,
    pub path: String,
    pub length_m: f64,
    /// Turns on the spot at corners.
    pub corner_stops: usize,
    pub speed_mps: f64,
    /// The limits followed (from the description, with the command line's overrides).
    pub kinematics: Kinematics,
    pub pose: Pose,
    pub goal: (f64, f64),
    pub repeat_forever: bool,
}

/// One progress report.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    pub time_s: f64,
    pub activity: &'static str,
    pub travelled_m: f64,
    pub remaining_m: Option<f64>,
    pub cross_track_m: f64,
    pub goal_distance_m: f64,
    pub pose: Pose,
    pub linear_mps: f64,
    /// Why the robot is held and for how long, s.
    pub held: Option<(String, f64)>,
    pub laps: u64,
}

/// The end.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub time_s: f64,
    pub goal_error_m: f64,
    pub travelled_m: f64,
    pub max_cross_track_m: f64,
    pub held_s: f64,
    pub pose: Pose,
}

/// Prints reports as text or JSON lines.
#[derive(Debug, Clone, Copy)]
pub struct Reporter {
    json: bool,
}

fn round(value: f64, places: i32) -> f64 {
    let scale = 10f64.powi(places);
    (value * scale).round() / scale
}

fn pose_json(pose: Pose) -> Value {
    json!({ "x_m": round(pose.x, 4), "y_m": round(pose.y, 4), "yaw_rad": round(pose.yaw, 4) })
}

/// A finite number, or null (JSON has no infinity).
fn finite(value: f64, places: i32) -> Value {
    json!(value.is_finite().then(|| round(value, places)))
}

fn limits_json(k: &Kinematics) -> Value {
    json!({
        "max_linear_mps": finite(k.max_linear_mps, 3),
        "max_reverse_mps": finite(k.max_reverse_mps, 3),
        "max_angular_radps": finite(k.max_angular_radps, 3),
        "lateral_mps": finite(k.lateral_mps, 3),
        "turns_on_the_spot": k.turns_on_the_spot(),
        "min_turn_radius_m": finite(k.min_turn_radius_m(), 3),
    })
}

/// `within 1.50 m/s, 0.52 rad/s, turning on the spot`.
fn limits_text(k: &Kinematics) -> String {
    let mut words = vec![format!("within {:.2} m/s", k.max_linear_mps)];
    if k.max_angular_radps.is_finite() {
        words.push(format!("{:.2} rad/s", k.max_angular_radps));
    }
    if k.lateral_mps > 0.0 {
        words.push(format!("{:.2} m/s sideways", k.lateral_mps));
    }
    words.push(if k.turns_on_the_spot() {
        "turning on the spot".to_string()
    } else {
        format!("turning no tighter than {:.2} m", k.min_turn_radius_m())
    });
    words.join(", ")
}

impl Reporter {
    pub fn new(json: bool) -> Self {
        Self { json }
    }

    fn line(&self, text: &str) {
        let mut out = std::io::stdout().lock();
        // A closed stdout must not stop the robot's controller.
        let _ = writeln!(out, "{text}");
        let _ = out.flush();
    }

    fn emit(&self, value: &Value) {
        self.line(&value.to_string());
    }

    pub fn start(&self, s: &Start) {
        if self.json {
            self.emit(&json!({
                "event": "start",
                "robot": s.robot,
                "described_as": s.described_as,
                "path": s.path,
                "length_m": round(s.length_m, 3),
                "corner_stops": s.corner_stops,
                "speed_mps": s.speed_mps,
                "limits": limits_json(&s.kinematics),
                "start": pose_json(s.pose),
                "goal": { "x_m": round(s.goal.0, 4), "y_m": round(s.goal.1, 4) },
                "repeat_forever": s.repeat_forever,
            }));
            return;
        }
        let corners = match s.corner_stops {
            0 => String::new(),
            1 => ", 1 turn on the spot".to_string(),
            n => format!(", {n} turns on the spot"),
        };
        let length = if s.repeat_forever {
            format!("{:.2} m a loop, repeated until stopped", s.length_m)
        } else {
            format!("{:.2} m", s.length_m)
        };
        self.line(&format!(
            "following {} ({length}{corners}): {} '{}' at {:.2} m/s ({}) from x {:.3} y {:.3} \
             yaw {:.1}°, goal x {:.3} y {:.3}",
            s.path,
            s.described_as,
            s.robot,
            s.speed_mps,
            limits_text(&s.kinematics),
            s.pose.x,
            s.pose.y,
            s.pose.yaw.to_degrees(),
            s.goal.0,
            s.goal.1
        ));
    }

    pub fn progress(&self, p: &Progress) {
        if self.json {
            self.emit(&json!({
                "event": "progress",
                "time_s": round(p.time_s, 2),
                "activity": p.activity,
                "travelled_m": round(p.travelled_m, 3),
                "remaining_m": p.remaining_m.map(|r| round(r, 3)),
                "cross_track_m": round(p.cross_track_m, 4),
                "goal_distance_m": round(p.goal_distance_m, 4),
                "pose": pose_json(p.pose),
                "linear_mps": round(p.linear_mps, 3),
                "held": p.held.as_ref().map(|(why, _)| why.clone()),
                "held_s": p.held.as_ref().map(|(_, s)| round(*s, 2)),
                "laps": p.laps,
            }));
            return;
        }
        let remaining = match p.remaining_m {
            Some(r) => format!("remaining {r:6.2} m"),
            None => format!("lap {}", p.laps + 1),
        };
        let held = p
            .held
            .as_ref()
            .map_or(String::new(), |(why, s)| format!("  [{why} for {s:.1} s]"));
        self.line(&format!(
            "{:6.1} s  {:<10} travelled {:6.2} m  {remaining}  cross-track {:+.3} m  {:.2} m/s{held}",
            p.time_s, p.activity, p.travelled_m, p.cross_track_m, p.linear_mps
        ));
    }

    /// A newer description of the robot changed the limits under way.
    pub fn limits(&self, time_s: f64, seq: u64, kinematics: &Kinematics) {
        if self.json {
            self.emit(&json!({
                "event": "limits",
                "time_s": round(time_s, 2),
                "description_seq": seq,
                "limits": limits_json(kinematics),
            }));
        } else {
            self.line(&format!(
                "{time_s:6.1} s  the robot's description changed (#{seq}): {}",
                limits_text(kinematics)
            ));
        }
    }

    /// A hold began (`held` true) or ended.
    pub fn hold(&self, time_s: f64, why: &str, held: bool, held_for_s: f64) {
        if self.json {
            self.emit(&json!({
                "event": if held { "preempted" } else { "resumed" },
                "time_s": round(time_s, 2),
                "reason": why,
                "held_s": round(held_for_s, 2),
            }));
        } else if held {
            self.line(&format!(
                "{time_s:6.1} s  {why}: waiting (the planner keeps asking)"
            ));
        } else {
            self.line(&format!(
                "{time_s:6.1} s  resumed after {held_for_s:.1} s ({why})"
            ));
        }
    }

    pub fn summary(&self, s: &Summary) {
        if self.json {
            self.emit(&json!({
                "event": "goal",
                "time_s": round(s.time_s, 2),
                "goal_error_m": round(s.goal_error_m, 4),
                "travelled_m": round(s.travelled_m, 3),
                "max_cross_track_m": round(s.max_cross_track_m, 4),
                "held_s": round(s.held_s, 2),
                "pose": pose_json(s.pose),
            }));
            return;
        }
        self.line(&format!(
            "reached the goal: {:.3} m from it after {:.1} s (travelled {:.2} m, largest \
             cross-track {:.3} m, held {:.1} s), pose x {:.3} y {:.3} yaw {:.1}°",
            s.goal_error_m,
            s.time_s,
            s.travelled_m,
            s.max_cross_track_m,
            s.held_s,
            s.pose.x,
            s.pose.y,
            s.pose.yaw.to_degrees()
        ));
    }

    /// The planner gives up (the reason also goes to stderr).
    pub fn failed(&self, time_s: f64, reason: &str) {
        if self.json {
            self.emit(&json!({ "event": "failed", "time_s": round(time_s, 2), "reason": reason }));
        }
    }

    pub fn interrupted(&self, time_s: f64) {
        if self.json {
            self.emit(&json!({ "event": "interrupted", "time_s": round(time_s, 2) }));
        } else {
            self.line(&format!("{time_s:6.1} s  interrupted: stopped the robot"));
        }
    }
}
