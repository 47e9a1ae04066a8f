//! The commands that talk to a running `chassisd`: echo, pub, status, control, sim.

use std::io::Write;
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{
    BusFrame, ChassisState, ClampFlags, ClientError, ControlKind, ControlMode, ControlRequest,
    ControlStatus, ControllerState, FaultFlags, FrameDirection, FrameKind, LinkFlags, LockStatus,
    MuxStatus, Robot, RobotDescription, SimKind, SimRequest, SimTruthPage, Source, SourceFlags,
    StopCategory, Ticker, ValidRequest, VelocityRequest, WireProtocol, ZeroReason,
    install_signal_handlers, now_ns, termination_requested,
};
use chassis_protocols::command_to_request;
use chassis_protocols::frame_json::driver_status_names;
use chassis_protocols::titan::BmsAlarm;
use clap::{Args, Subcommand, ValueEnum};

use crate::action::{Action, OnOff, VelocityArgs};
use crate::described;

/// How long a request may wait for the service's answer.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(3);

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Topic {
    /// ChassisState samples.
    State,
    /// Bus frames, both directions.
    Frames,
    /// Mux decisions.
    Mux,
}

#[derive(Debug, Args)]
pub struct EchoArgs {
    #[arg(value_enum)]
    pub topic: Topic,
    /// The robot's name (chassisd --name).
    #[arg(long, default_value = "titan")]
    pub name: String,
    /// One JSON object per line.
    #[arg(long)]
    pub json: bool,
    /// Stop after this many samples.
    #[arg(long)]
    pub count: Option<u64>,
}

#[derive(Debug, Args)]
pub struct PubArgs {
    /// The configured source to publish as (safety, teleop, planner, …).
    #[arg(long)]
    pub source: String,
    #[command(flatten)]
    pub velocity: VelocityArgs,
    /// Requests per second.
    #[arg(long, default_value_t = 20.0)]
    pub rate: f64,
    /// Seconds to publish for; 0 = until Ctrl-C. A stop follows.
    #[arg(long, default_value_t = 0.0)]
    pub duration: f64,
    /// Send heartbeats ("alive, asking for nothing") instead of a velocity.
    #[arg(long)]
    pub heartbeat: bool,
    #[arg(long, default_value = "titan")]
    pub name: String,
}

#[derive(Debug, Subcommand)]
pub enum ControlCmd {
    #[command(flatten)]
    Action(Action),
    /// Release the e-stop lock (after a safety latch or an operator e-stop).
    EstopRelease,
    /// Engage the e-stop lock as the operator: nothing below its priority moves.
    Estop {
        /// The stop category (IEC 60204-1): 0 cuts the drive at once, 1 brakes and then cuts
        /// it, 2 brakes and holds; default: the lock's configured one (`chassis status` shows it).
        #[arg(long, value_parser = clap::value_parser!(u8).range(0..=2))]
        category: Option<u8>,
    },
    /// Release a named lock.
    LockRelease { lock: String },
    /// Engage a named lock as the operator.
    LockEngage {
        lock: String,
        /// The stop category (0, 1 or 2); default: the lock's configured one.
        #[arg(long, value_parser = clap::value_parser!(u8).range(0..=2))]
        category: Option<u8>,
    },
    /// Set the robot's speed limit as the operator, m/s: raise or lower it; 0 lifts it (any
    /// client may lower it, only the operator raises it).
    SpeedLimit { mps: f32 },
    /// Keep the black box's window around now as a file in the state directory's
    /// `blackbox/kept/` (`chassis explain FILE` tells it).
    Keep,
}

#[derive(Debug, Subcommand)]
pub enum SimCmd {
    /// Obstacle ahead at RANGE m (XBot ultrasonic); --clear removes it.
    ObstacleAhead {
        range: Option<f64>,
        #[arg(long)]
        clear: bool,
    },
    /// Obstacle behind at RANGE m (XBot IR); --clear removes it.
    ObstacleBehind {
        range: Option<f64>,
        #[arg(long)]
        clear: bool,
    },
    /// Power-cycle the chassis.
    Reboot,
    /// Battery state of charge, %.
    Battery { soc_pct: f64 },
    /// Press or release the bumper.
    Bumper {
        #[arg(value_enum)]
        state: OnOff,
    },
    /// An RC transmitter takes over (on) or is switched off.
    Rc {
        #[arg(value_enum)]
        state: OnOff,
    },
    /// The chassis' own emergency-stop switch pressed (on) or released (AgileX V2 robots).
    EstopSwitch {
        #[arg(value_enum)]
        state: OnOff,
    },
    /// Motor driver N lost (on) or back (off).
    MotorLoss {
        motor: u8,
        #[arg(value_enum)]
        state: OnOff,
    },
    /// The chassis stops transmitting for SECONDS.
    Silence { seconds: f64 },
    /// BYTES of garbage on the wire.
    Garbage { bytes: u32 },
    /// Corrupt the checksum of the next FRAMES frames.
    BadChecksums { frames: u32 },
    /// FRAMES_PER_S extra feedback frames (0 stops).
    Flood { frames_per_s: u32 },
    /// What the simulated chassis really does: its true pose and speeds (not what it reports);
    /// --injected: the garbage, bad-checksum and flood frames it has sent since power-up.
    Truth {
        #[arg(long)]
        injected: bool,
    },
    /// The speed loop runs away: the chassis drives at SPEED m/s (negative: reverse) whatever
    /// it is commanded, past its limits; --clear gives the control back.
    Runaway {
        #[arg(allow_negative_numbers = true)]
        speed: Option<f64>,
        #[arg(long)]
        clear: bool,
    },
    /// The wheels turn at GAIN times the command: 0 ignores it, 0 to 1 slips, negative drives
    /// against it (at most 2 either way); --clear makes the chassis obey again.
    Gain {
        #[arg(allow_negative_numbers = true)]
        gain: Option<f64>,
        #[arg(long)]
        clear: bool,
    },
}

/// `chassis echo`.
pub fn echo(args: &EchoArgs) -> anyhow::Result<()> {
    install_signal_handlers();
    let mut robot = Robot::connect(&args.name)?;
    let mut out = std::io::stdout().lock();
    let mut printed = 0u64;
    let mut quiet_since = now_ns();
    let tap = match args.topic {
        Topic::Frames => Some(robot.frames(1024)?),
        _ => None,
    };
    let mut last_frame_seq = 0u64;
    let mut lost = 0u64;
    while args.count.is_none_or(|c| printed < c) && !termination_requested() {
        let got = match args.topic {
            Topic::State => {
                let state = robot.wait_state(Duration::from_millis(500))?;
                write_sample(&mut out, args.json, state.as_ref(), state_line)?
            }
            Topic::Mux => {
                let mux = robot.wait_mux(Duration::from_millis(500))?;
                write_sample(&mut out, args.json, mux.as_ref(), mux_line)?
            }
            Topic::Frames => {
                let Some(tap) = &tap else { break };
                let mut lines = Vec::new();
                let limit = args.count.map_or(u64::MAX, |c| c - printed);
                tap.wait(Duration::from_millis(500), |frame| {
                    if last_frame_seq != 0 && frame.seq > last_frame_seq + 1 {
                        lost += frame.seq - last_frame_seq - 1;
                    }
                    last_frame_seq = frame.seq;
                    if (lines.len() as u64) < limit {
                        lines.push(if args.json {
                            frame_json(frame).to_string()
                        } else {
                            frame_line(frame)
                        });
                    }
                })?;
                let got = lines.len();
                for line in lines {
                    writeln!(out, "{line}")?;
                }
                got
            }
        };
        out.flush()?;
        printed += got as u64;
        if got > 0 {
            quiet_since = now_ns();
        } else if now_ns().saturating_sub(quiet_since) > 2_000_000_000 {
            if !robot.is_served() {
                bail!("chassis/{} is gone — is chassisd still running?", args.name);
            }
            quiet_since = now_ns();
        }
    }
    if lost > 0 {
        eprintln!("{lost} frames were lost between reads (sequence gaps)");
    }
    Ok(())
}

/// Writes `sample`, when one came, as JSON or as its text line; how many were written.
pub(crate) fn write_sample<T: serde::Serialize>(
    out: &mut impl Write,
    json: bool,
    sample: Option<&T>,
    line: fn(&T) -> String,
) -> anyhow::Result<usize> {
    let Some(sample) = sample else {
        return Ok(0);
    };
    if json {
        writeln!(out, "{}", serde_json::to_string(sample)?)?;
    } else {
        writeln!(out, "{}", line(sample))?;
    }
    Ok(1)
}

fn age_text(stamp_ns: u64) -> String {
    if stamp_ns == 0 {
        return "never".into();
    }
    format!("{:.0} ms", now_ns().saturating_sub(stamp_ns) as f64 / 1e6)
}

/// One line per state sample.
pub fn state_line(s: &ChassisState) -> String {
    let faults = FaultFlags::names(s.system.fault_flags & !FaultFlags::WARNINGS);
    let warnings = FaultFlags::names(s.system.fault_flags & FaultFlags::WARNINGS);
    format!(
        "#{:<6} {:>7.3} m/s {:>7.3} rad/s steer {:>6.3}  pose ({:.2}, {:.2}, {:.1}°)  {}  {:.1} V  faults {}{}{}",
        s.seq,
        s.motion.linear_mps,
        s.motion.angular_radps,
        s.motion.steer_rad,
        s.odometry.x_m,
        s.odometry.y_m,
        s.odometry.yaw_rad.to_degrees(),
        ControlMode::name(s.system.control_mode),
        s.system.battery_voltage_v,
        if faults.is_empty() {
            "-".to_string()
        } else {
            faults.join(",")
        },
        if warnings.is_empty() {
            String::new()
        } else {
            format!("  warnings {}", warnings.join(","))
        },
        if s.link_flags & (LinkFlags::CHASSIS_SILENT | LinkFlags::BUS_DOWN) != 0 {
            format!("  [{}]", LinkFlags::names(s.link_flags).join(","))
        } else {
            String::new()
        }
    )
}

/// One line per mux decision.
pub fn mux_line(m: &MuxStatus) -> String {
    let active = m.active().map_or("none".to_string(), |s| {
        format!("{} ({})", s.name(), s.priority)
    });
    format!(
        "#{:<5} active {:<16} out vx {:>6.3} vy {:>6.3} wz {:>6.3}  reason {}  clamped {}  locks {}",
        m.seq,
        active,
        m.output.linear_x_mps,
        m.output.linear_y_mps,
        m.output.angular_z_radps,
        ZeroReason::name(m.zero_reason),
        if m.clamp_flags == 0 {
            "-".to_string()
        } else {
            ClampFlags::names(m.clamp_flags).join(",")
        },
        locks_text(m)
    )
}

fn locks_text(m: &MuxStatus) -> String {
    if m.locks().is_empty() {
        return "-".into();
    }
    m.locks()
        .iter()
        .map(|l| {
            if l.held == 0 {
                format!("{} free (stops with category {})", l.name(), l.category)
            } else {
                format!(
                    "{} HELD by {}, stop category {}",
                    l.name(),
                    lock_holder(m, l),
                    StopCategory::text(l.category)
                )
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Who holds `lock`: `operator` (a control request), the source's name, or `?` for an index
/// `m` has no source at.
pub(crate) fn lock_holder(m: &MuxStatus, lock: &LockStatus) -> String {
    match lock.holder {
        LockStatus::HOLDER_OPERATOR => "operator".to_string(),
        i => m
            .sources()
            .get(usize::from(i))
            .map_or("?".to_string(), |s| s.name().to_string()),
    }
}

/// `  12.345678 RX 111#0096000000000000` (CAN) or `RX AA 55 02 01 01 02` (serial).
pub fn frame_line(frame: &BusFrame) -> String {
    let t = frame.stamp_ns as f64 / 1e9;
    let dir = FrameDirection::name(frame.direction).to_uppercase();
    match frame.kind {
        FrameKind::CAN => {
            let id = if frame.flags & BusFrame::EXTENDED_ID != 0 {
                format!("{:08X}", frame.can_id)
            } else {
                format!("{:03X}", frame.can_id)
            };
            format!(
                "{t:>14.6} {dir} {id}#{}",
                hex::encode_upper(frame.payload())
            )
        }
        FrameKind::GPS => format!(
            "{t:>14.6} GPS {}",
            String::from_utf8_lossy(frame.payload()).trim_end()
        ),
        _ => format!(
            "{t:>14.6} {dir} {}",
            frame
                .payload()
                .iter()
                .map(|b| format!("{b:02X}"))
                .collect::<Vec<_>>()
                .join(" ")
        ),
    }
}

fn frame_json(frame: &BusFrame) -> serde_json::Value {
    let mut value = serde_json::to_value(frame).unwrap_or(serde_json::Value::Null);
    if let Some(obj) = value.as_object_mut() {
        obj.insert("data".into(), hex::encode_upper(frame.payload()).into());
    }
    value
}

/// `chassis pub velocity`.
pub fn publish(args: &PubArgs) -> anyhow::Result<()> {
    install_signal_handlers();
    if !(args.rate > 0.0 && args.rate <= 10_000.0) {
        bail!("--rate must be above 0 and at most 10000 Hz");
    }
    // Parsed once: a NaN or an infinity is refused before anything is sent.
    let request = ValidRequest::try_from(if args.heartbeat {
        VelocityRequest::heartbeat()
    } else {
        args.velocity.request()
    })?;
    let connect =
        || -> Result<Source, ClientError> { Robot::connect(&args.name)?.source(&args.source) };
    // The first connection must work; after it, a chassisd that goes away (restarted by
    // systemd, say) is waited for, and the stream goes on once it is back. It is the same
    // process reconnecting, so it sends no zero of its own: the robot moves again only once this
    // stream asks for a zero (docs/ARCHITECTURE.md, "Motion starts only from a zero").
    let mut source = Some(connect()?);
    let start = now_ns();
    let end = (args.duration > 0.0).then(|| start + (args.duration * 1e9) as u64);
    let mut ticker = Ticker::new(Duration::from_secs_f64(1.0 / args.rate));
    let mut sent = 0u64;
    while !termination_requested() && end.is_none_or(|e| now_ns() < e) {
        if source.is_none() {
            source = connect().ok();
        }
        if let Some(s) = &mut source {
            match s.send(request) {
                Ok(()) => sent += 1,
                Err(e) => {
                    eprintln!("chassisd for {} went away ({e}): waiting for it", args.name);
                    source = None;
                }
            }
        }
        ticker.wait();
    }
    if let Some(s) = &mut source
        && !args.heartbeat
    {
        s.stop()?;
    }
    eprintln!(
        "sent {sent} requests as {} over {:.1} s{}",
        args.source,
        now_ns().saturating_sub(start) as f64 / 1e9,
        if args.heartbeat { "" } else { ", then a stop" }
    );
    Ok(())
}

/// `chassis status`: a human summary.
pub fn status(name: &str, json: bool) -> anyhow::Result<()> {
    let mut robot = Robot::connect(name)?;
    let mux = match robot.latest_mux()? {
        Some(m) => Some(m),
        None => robot.wait_mux(Duration::from_secs(1))?,
    };
    // A fresh sample, not the one the subscription inherited (it is as old as our start-up).
    let inherited = robot.latest_state()?;
    let state = robot.wait_state(Duration::from_millis(500))?.or(inherited);
    let age = state.map_or(String::new(), |s| age_text(s.stamp_ns));
    // What the robot is (published with history 1: a new reader has it within a tick).
    let description = match robot.description(Duration::from_millis(500)) {
        Ok(d) => Some(d),
        Err(chassis_client::ClientError::NoDescription { .. }) => None,
        Err(e) => return Err(e.into()),
    };
    // The safety monitor's status, when one has made its service (a new reader gets the latest
    // sample with the monitor's next publication, at least every 100 ms).
    let safety = robot
        .subscriber::<chassis_client::SafetyStatus>(chassis_client::SafetyStatus::SERVICE)?
        .map(|mut subscription| subscription.wait(Duration::from_millis(300)))
        .transpose()?;
    if json {
        println!(
            "{}",
            serde_json::json!({
                "name": name,
                "description": description.as_ref().map(described::json),
                "state": state,
                "mux": mux,
                "safety": safety.flatten(),
            })
        );
        return Ok(());
    }
    let Some(s) = state else {
        bail!("chassis/{name} published no state within 1 s");
    };
    print!("{}", state_report(name, &s, description.as_ref(), &age));
    if let Some(m) = mux {
        println!("{}", mux_summary(&m));
    }
    if let Some(safety) = safety {
        println!("{}", safety_summary(safety.as_ref()));
    }
    Ok(())
}

/// What `chassis status` says about one state sample: the robot as chassisd describes it
/// (model, limits, sensors, joints), bus, mode, motion, command, battery against the described
/// levels, faults and warnings by name (with the chassis' own fault word), where the robot
/// reports them its motor drivers' status bits and its BMS alarms, and the configured sources.
fn state_report(
    name: &str,
    s: &ChassisState,
    description: Option<&RobotDescription>,
    age: &str,
) -> String {
    let mut lines = Vec::new();
    match description {
        Some(d) => {
            lines.push(format!(
                "robot      {} · chassis/{name}   state #{}, {age} old",
                described::title(d),
                s.seq,
            ));
            lines.push(format!("model      {}", described::model_line(d)));
            lines.push(format!("limits     {}", described::limits_line(d)));
            if let Some(origin) = described::limits_origin_line(d) {
                lines.push(format!("           {origin}"));
            }
            if let Some(sensors) = described::sensors_line(d) {
                lines.push(format!("sensors    {sensors}"));
            }
            if let Some(joints) = described::joints_line(d) {
                lines.push(format!("joints     {joints}"));
            }
        }
        None => lines.push(format!(
            "robot      robot kind {} (chassis/{name}, no description: chassisd older than the \
             robot description?)   state #{}, {age} old",
            s.robot, s.seq,
        )),
    }
    let link = &s.link;
    let health = if s.has_link_flag(LinkFlags::BUS_DOWN) {
        "DOWN"
    } else if s.has_link_flag(LinkFlags::CAN_BUS_OFF) {
        "BUS-OFF"
    } else if s.has_link_flag(LinkFlags::CHASSIS_SILENT) {
        "chassis silent"
    } else {
        "ok"
    };
    lines.push(format!(
        "bus        {health}: rx {} frames, tx {}, bad checksums {}, decode errors {}, unknown ids {}, discarded bytes {}, reconnects {}",
        link.rx_frames,
        link.tx_frames,
        link.rx_bad_checksum,
        link.rx_decode_errors,
        link.rx_unknown_id,
        link.rx_bytes_discarded,
        link.bus_reconnects
    ));
    if link.can_state != ControllerState::UNKNOWN || link.can_error_frames > 0 {
        lines.push(format!(
            "can        {}   error counters tx {} rx {}   error frames {}, error-passive {}, \
             bus-off {}, restarts {}, bus errors {}, unacknowledged {}",
            ControllerState::name(link.can_state),
            link.can_tx_error_count,
            link.can_rx_error_count,
            link.can_error_frames,
            link.can_error_passive,
            link.can_bus_off,
            link.can_restarts,
            link.can_bus_errors,
            link.can_no_ack,
        ));
    }
    if link.recorder_dropped > 0 {
        lines.push(format!(
            "black box  {} passes unrecorded: the recorder fell behind (a slow or full disk)",
            link.recorder_dropped
        ));
    }
    lines.push(format!(
        "mode       {}   protocol {}   flags {}",
        ControlMode::name(s.system.control_mode),
        WireProtocol::name(s.system.wire_protocol),
        LinkFlags::names(s.link_flags).join(", ")
    ));
    lines.push(format!(
        "motion     {:.3} m/s  {:.3} rad/s  steer {:.3} rad   pose x {:.2} m  y {:.2} m  yaw {:.1}°",
        s.motion.linear_mps,
        s.motion.angular_radps,
        s.motion.steer_rad,
        s.odometry.x_m,
        s.odometry.y_m,
        s.odometry.yaw_rad.to_degrees()
    ));
    lines.push(format!(
        "command    {:.3} m/s  {:.3} rad/s  steer {:.3} rad  clamped {}",
        s.command.linear_mps,
        s.command.angular_radps,
        s.command.steer_rad,
        ClampFlags::names(s.command.clamp_flags).join(", ")
    ));
    lines.push(format!(
        "battery    {}",
        described::battery_line(Some(s), description)
    ));
    let listed = |bits: u64| listed_names(&FaultFlags::names(bits));
    lines.push(format!(
        "faults     {}",
        listed(s.system.fault_flags & !FaultFlags::WARNINGS)
    ));
    lines.push(format!(
        "warnings   {}",
        listed(s.system.fault_flags & FaultFlags::WARNINGS)
    ));
    if s.system.vendor_fault_word != 0 {
        lines.push(format!(
            "chassis    fault word 0x{:04x}",
            s.system.vendor_fault_word
        ));
    }
    if s.is_valid(chassis_client::Group::MotorDriver) {
        let drivers: Vec<String> = s
            .motors
            .iter()
            .enumerate()
            .filter(|(_, m)| m.driver_voltage_v != 0.0 || m.driver_status != 0)
            .map(|(i, m)| {
                let mut names = driver_status_names(m.driver_status);
                let enabled = names.iter().any(|n| n == "enabled");
                names.retain(|n| n != "enabled");
                format!(
                    "{} {}{}",
                    i + 1,
                    if enabled { "enabled" } else { "disabled" },
                    if names.is_empty() {
                        String::new()
                    } else {
                        format!(" ({})", names.join(", "))
                    }
                )
            })
            .collect();
        if !drivers.is_empty() {
            lines.push(format!("drivers    {}", drivers.join(", ")));
        }
    }
    for (group, bms) in s.bms.iter().enumerate() {
        if bms.alarm_flags != 0 {
            let alarm = BmsAlarm::from_alarm_flags(group as u8, bms.alarm_flags);
            lines.push(format!(
                "bms {group}      alarms {}   warnings {}",
                listed_names(&alarm.alarm_names()),
                listed_names(&alarm.warning_names())
            ));
        }
    }
    if let Some(d) = description {
        lines.push(format!("config     {}", described::sources_line(d)));
    }
    let mut text = lines.join("\n");
    text.push('\n');
    text
}

fn listed_names(names: &[&str]) -> String {
    if names.is_empty() {
        "none".to_string()
    } else {
        names.join(", ")
    }
}

/// The safety monitor's `SafetyStatus` (`None`: its service exists but nothing was published).
fn safety_summary(status: Option<&chassis_client::SafetyStatus>) -> String {
    use chassis_client::{EstopState, SafetyAction, SafetyRule, SafetyStatus};
    let Some(s) = status else {
        return "safety     no monitor publishing (its service exists, no status within 300 ms)"
            .into();
    };
    let age_ms = now_ns().saturating_sub(s.stamp_ns) / 1_000_000;
    let alive = if age_ms < 500 {
        format!("alive, {age_ms} ms old")
    } else {
        format!("SILENT for {age_ms} ms")
    };
    let limit = |v: f32, unit: &str| {
        if v >= SafetyStatus::UNLIMITED {
            "free".to_string()
        } else {
            format!("≤ {v:.2} {unit}")
        }
    };
    let action = match s.action {
        SafetyAction::NONE => "all clear".to_string(),
        SafetyAction::SLOW => format!(
            "SLOW by {} (forward {}, reverse {}, lateral {}, yaw {})",
            SafetyRule::names(s.active_rules).join(", "),
            limit(s.limit_forward_mps, "m/s"),
            limit(s.limit_reverse_mps, "m/s"),
            limit(s.limit_lateral_mps, "m/s"),
            limit(s.limit_angular_radps, "rad/s")
        ),
        _ => s.why(),
    };
    let mut out = format!(
        "safety     {alive} · {action} · estop {}",
        EstopState::name(s.estop)
    );
    if s.acknowledged_rules != 0 {
        out.push_str(&format!(
            " · acknowledged {}",
            SafetyRule::names(s.acknowledged_rules).join(", ")
        ));
    }
    let counts: Vec<String> = (0..SafetyRule::COUNT as u8)
        .filter(|&r| s.trigger_count(r) > 0)
        .map(|r| format!("{} {}", SafetyRule::name(r), s.trigger_count(r)))
        .collect();
    if s.last_event_ns != 0 {
        out.push_str(&format!(
            "\n           last {} ago: {}",
            age_text(s.last_event_ns),
            s.last_text()
        ));
    }
    if !counts.is_empty() {
        out.push_str(&format!(" · triggers {}", counts.join(", ")));
    }
    out
}

fn mux_summary(m: &MuxStatus) -> String {
    let mut out = String::new();
    let active = match m.active() {
        Some(s) => format!(
            "{} (priority {}, {} ms old)",
            s.name(),
            s.priority,
            m.active_age_ms
        ),
        None => format!("none — {}", m.why()),
    };
    out.push_str(&format!(
        "mux        active {active}   output vx {:.3} vy {:.3} wz {:.3}\n",
        m.output.linear_x_mps, m.output.linear_y_mps, m.output.angular_z_radps
    ));
    let sources: Vec<String> = m
        .sources()
        .iter()
        .map(|s| {
            let mut words = vec![format!("{} {}", s.name(), s.priority)];
            if s.has(SourceFlags::REQUIRED) {
                words.push("required".into());
            }
            words.push(if s.age_ms == u32::MAX {
                "never".into()
            } else if s.has(SourceFlags::FRESH) {
                format!("fresh {} ms", s.age_ms)
            } else {
                format!("stale {} ms", s.age_ms)
            });
            if s.has(SourceFlags::HEARTBEAT) {
                words.push("heartbeat".into());
            }
            if s.has(SourceFlags::ACTIVE) {
                words.push("ACTIVE".into());
            }
            if s.has(SourceFlags::BLOCKED) {
                words.push("blocked".into());
            }
            if s.has(SourceFlags::AWAITING_ZERO) {
                words.push("awaiting zero".into());
            }
            if s.rejected > 0 {
                words.push(format!("{} rejected", s.rejected));
            }
            words.join(" ")
        })
        .collect();
    out.push_str(&format!("sources    {}\n", sources.join(" | ")));
    out.push_str(&format!("locks      {}", locks_text(m)));
    if let Some((mps, holder)) = m.speed_limit() {
        out.push_str(&format!("\nlimit      {mps} m/s, set by {holder}"));
    }
    out
}

fn print_answer(response: &chassis_client::ControlResponse) -> anyhow::Result<()> {
    if response.is_ok() {
        println!("ok: {}", response.message());
        Ok(())
    } else {
        bail!(
            "{}: {}",
            ControlStatus::name(response.status),
            response.message()
        )
    }
}

/// `chassis control …`.
pub fn control(name: &str, command: &ControlCmd) -> anyhow::Result<()> {
    let request = match command {
        ControlCmd::Action(action) => {
            let command = action.to_command().map_err(anyhow::Error::msg)?;
            command_to_request(&command).context("motion is not a control request")?
        }
        ControlCmd::EstopRelease => {
            ControlRequest::new(ControlKind::LOCK_RELEASE).with_name("estop")
        }
        ControlCmd::Estop { category } => ControlRequest::new(ControlKind::LOCK_ENGAGE)
            .with_name("estop")
            .with_arg(0, category.map_or(0, |c| c + 1)),
        ControlCmd::LockRelease { lock } => {
            ControlRequest::new(ControlKind::LOCK_RELEASE).with_name(lock)
        }
        ControlCmd::LockEngage { lock, category } => ControlRequest::new(ControlKind::LOCK_ENGAGE)
            .with_name(lock)
            .with_arg(0, category.map_or(0, |c| c + 1)),
        ControlCmd::SpeedLimit { mps } => {
            ControlRequest::new(ControlKind::SPEED_LIMIT).with_value(0, *mps)
        }
        ControlCmd::Keep => ControlRequest::new(ControlKind::KEEP),
    };
    let mut robot = Robot::connect(name)?;
    let response = robot.control(request, ANSWER_TIMEOUT)?;
    print_answer(&response)
}

/// `chassis sim …`.
pub fn sim(name: &str, command: &SimCmd) -> anyhow::Result<()> {
    let request = |kind: u8, flag: bool, index: u8, value: f64| SimRequest {
        kind,
        flag: u8::from(flag),
        index,
        value,
        ..SimRequest::default()
    };
    let range = |range: &Option<f64>, clear: bool| -> anyhow::Result<(bool, f64)> {
        match (range, clear) {
            (_, true) => Ok((false, 0.0)),
            (Some(r), false) if r.is_finite() && *r >= 0.0 => Ok((true, *r)),
            _ => bail!("give a range in metres, or --clear"),
        }
    };
    let r = match command {
        SimCmd::ObstacleAhead { range: d, clear } => {
            let (on, d) = range(d, *clear)?;
            request(SimKind::OBSTACLE_AHEAD, on, 0, d)
        }
        SimCmd::ObstacleBehind { range: d, clear } => {
            let (on, d) = range(d, *clear)?;
            request(SimKind::OBSTACLE_BEHIND, on, 0, d)
        }
        SimCmd::Reboot => request(SimKind::REBOOT, true, 0, 0.0),
        SimCmd::Battery { soc_pct } => request(SimKind::BATTERY, true, 0, *soc_pct),
        SimCmd::Bumper { state } => request(SimKind::BUMPER, state.is_on(), 0, 0.0),
        SimCmd::Rc { state } => request(SimKind::RC_TAKEOVER, state.is_on(), 0, 0.0),
        SimCmd::EstopSwitch { state } => request(SimKind::ESTOP_SWITCH, state.is_on(), 0, 0.0),
        SimCmd::MotorLoss { motor, state } => {
            request(SimKind::MOTOR_DRIVER_LOSS, state.is_on(), *motor, 0.0)
        }
        SimCmd::Silence { seconds } => request(SimKind::SILENCE, true, 0, *seconds),
        SimCmd::Garbage { bytes } => request(SimKind::GARBAGE, true, 0, f64::from(*bytes)),
        SimCmd::BadChecksums { frames } => {
            request(SimKind::BAD_CHECKSUMS, true, 0, f64::from(*frames))
        }
        SimCmd::Flood { frames_per_s } => chassis_client::flood_request(f64::from(*frames_per_s)),
        SimCmd::Truth { injected } => {
            let page = if *injected {
                SimTruthPage::INJECTED
            } else {
                SimTruthPage::MOTION
            };
            request(SimKind::TRUTH, false, page, 0.0)
        }
        SimCmd::Runaway { speed, clear } => match (speed, clear) {
            (_, true) => request(SimKind::RUNAWAY, false, 0, 0.0),
            (Some(v), false) if v.is_finite() => request(SimKind::RUNAWAY, true, 0, *v),
            _ => bail!("give a speed in m/s, or --clear"),
        },
        SimCmd::Gain { gain, clear } => match (gain, clear) {
            (_, true) => request(SimKind::GAIN, false, 0, 0.0),
            (Some(g), false) if g.is_finite() => request(SimKind::GAIN, true, 0, *g),
            _ => bail!("give a gain, or --clear"),
        },
    };
    let mut robot = Robot::connect(name)?;
    let response = robot.sim(r, ANSWER_TIMEOUT)?;
    print_answer(&response)
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::{CanFrame, Driver, DriverConfig, RobotKind, Rx, Timestamp};

    /// The state the robot's own driver (default profile) makes of `frames`.
    fn state_of(robot: RobotKind, frames: &[&str]) -> ChassisState {
        let entry = robot.entry();
        let now = Timestamp::from_millis(1_000);
        let mut driver = entry.driver(&entry.defaults(), false, &DriverConfig::default(), now);
        for frame in frames {
            driver.handle_rx(now, Rx::Can(&CanFrame::from_candump(frame).unwrap()));
        }
        *driver.state()
    }

    fn line<'a>(report: &'a str, head: &str) -> &'a str {
        report
            .lines()
            .find(|l| {
                l.strip_prefix(head)
                    .is_some_and(|rest| rest.starts_with(' '))
            })
            .unwrap_or_else(|| panic!("no '{head}' line in\n{report}"))
    }

    #[test]
    fn status_names_a_v2_bunkers_estop_drivers_and_bms_alarms() {
        // TV8 (BUNKER MINI 2.0, E-stop pressed), a driver at 24 V enabled, a BMS alarm, and
        // 0x211 again (the BMS alarm joins the faults with it).
        let s = state_of(
            RobotKind::Bunker,
            &[
                "211#0100010000800000",
                "261#00F0001E1E400000",
                "362#04010800",
                "211#0100010000800000",
            ],
        );
        let described =
            chassis_protocols::description::describe(&RobotKind::Bunker.entry().defaults());
        let report = state_report("bunker", &s, Some(&described), "5 ms");
        assert!(
            line(&report, "robot")
                .starts_with("robot      AgileX BUNKER (bunker) · chassis/bunker"),
            "{report}"
        );
        let without = state_report("bunker", &s, None, "5 ms");
        assert!(
            line(&without, "robot").contains("no description"),
            "{without}"
        );
        assert!(
            line(&report, "mode").contains("standby   protocol v2"),
            "{report}"
        );
        assert_eq!(line(&report, "faults"), "faults     emergency_stop");
        assert_eq!(line(&report, "warnings"), "warnings   bms_alarm");
        assert_eq!(line(&report, "chassis"), "chassis    fault word 0x0080");
        assert_eq!(line(&report, "drivers"), "drivers    1 enabled");
        assert_eq!(
            line(&report, "bms 0"),
            "bms 0      alarms under_voltage, charge_over_current   warnings over_temperature"
        );
    }

    #[test]
    fn status_says_bus_off_and_the_can_controllers_counts() {
        let mut s = state_of(RobotKind::Titan, &[]);
        let report = state_report("titan", &s, None, "5 ms");
        assert!(!report.contains("\ncan "), "{report}");
        s.link_flags |= LinkFlags::CAN_BUS_OFF | LinkFlags::CHASSIS_SILENT;
        s.link.can_state = ControllerState::BUS_OFF;
        (s.link.can_tx_error_count, s.link.can_rx_error_count) = (255, 3);
        (
            s.link.can_error_frames,
            s.link.can_bus_off,
            s.link.can_restarts,
        ) = (4, 2, 1);
        let report = state_report("titan", &s, None, "5 ms");
        assert!(
            line(&report, "bus").starts_with("bus        BUS-OFF: "),
            "{report}"
        );
        assert_eq!(
            line(&report, "can"),
            "can        bus-off   error counters tx 255 rx 3   error frames 4, error-passive 0, \
             bus-off 2, restarts 1, bus errors 0, unacknowledged 0"
        );
    }

    #[test]
    fn status_counts_the_passes_the_black_box_dropped() {
        let mut s = state_of(RobotKind::Titan, &[]);
        let report = state_report("titan", &s, None, "5 ms");
        assert!(!report.contains("\nblack box "), "{report}");
        s.link.recorder_dropped = 7;
        let report = state_report("titan", &s, None, "5 ms");
        assert_eq!(
            line(&report, "black box"),
            "black box  7 passes unrecorded: the recorder fell behind (a slow or full disk)"
        );
    }

    #[test]
    fn status_reads_a_hunters_driver_bit_6_as_disabled() {
        // ⚠ D-7: HUNTER 2.0's bit 6 set means disabled; bit 0 is supply under-voltage.
        let s = state_of(
            RobotKind::Hunter,
            &["211#0001010000000000", "261#00F0001E1E410000"],
        );
        let report = state_report("hunter", &s, None, "5 ms");
        assert_eq!(line(&report, "faults"), "faults     none");
        assert_eq!(
            line(&report, "drivers"),
            "drivers    1 disabled (supply_under_voltage)"
        );
        assert!(!report.contains("chassis    fault word"), "{report}");
    }
}
