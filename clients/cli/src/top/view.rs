//! The dashboard's panels, built once from a [`Snapshot`] and shown either as ratatui blocks
//! or as plain text (`--once`).

use chassis_client::{
    ChassisState, ClampFlags, ControlMode, ControllerState, FaultFlags, FrameDirection, LinkFlags,
    LockStatus, MuxStatus, RobotDescription, SourceFlags,
};
use ratatui::Frame;
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph};

use super::stats::{BusStats, Latency, Samples, WINDOW_NS};
use crate::described;

/// Everything one screen shows.
#[derive(Debug)]
pub struct Snapshot<'a> {
    pub name: &'a str,
    pub now_ns: u64,
    /// How long the dashboard has been collecting, ns.
    pub running_ns: u64,
    /// What chassisd says the robot is (`None`: an older chassisd, or not yet).
    pub description: Option<&'a RobotDescription>,
    pub state: Option<&'a ChassisState>,
    pub mux: Option<&'a MuxStatus>,
    pub bus: &'a BusStats,
    pub latency: &'a Latency,
}

/// A titled block of lines.
#[derive(Debug)]
pub struct Panel {
    pub title: &'static str,
    pub lines: Vec<Line<'static>>,
}

fn bold(color: Color) -> Style {
    Style::default().fg(color).add_modifier(Modifier::BOLD)
}

fn dim(text: String) -> Span<'static> {
    Span::styled(text, Style::default().fg(Color::DarkGray))
}

fn label(text: &str) -> Span<'static> {
    dim(format!("{text:<10}"))
}

/// A line of a panel: its label, then `text`.
fn row(name: &str, text: impl Into<String>) -> Line<'static> {
    Line::from(vec![label(name), Span::raw(text.into())])
}

/// `850 µs`, `12.3 ms`, `1.20 s`.
pub fn duration_text(ns: u64) -> String {
    if ns < 1_000_000 {
        format!("{} µs", ns / 1_000)
    } else if ns < 1_000_000_000 {
        format!("{:.1} ms", ns as f64 / 1e6)
    } else {
        format!("{:.2} s", ns as f64 / 1e9)
    }
}

/// The four panels: robot, mux, bus, latency.
pub fn panels(s: &Snapshot) -> [Panel; 4] {
    [
        ("robot", robot_panel(s)),
        ("mux", mux_panel(s)),
        ("bus", bus_panel(s)),
        ("latency", latency_panel(s)),
    ]
    .map(|(title, lines)| Panel { title, lines })
}

fn robot_panel(s: &Snapshot) -> Vec<Line<'static>> {
    let mut lines = Vec::new();
    let Some(st) = s.state else {
        lines.push(Line::from(format!("no state from chassis/{} yet", s.name)));
        return lines;
    };
    let age = s.now_ns.saturating_sub(st.stamp_ns);
    let title = s.description.map_or_else(
        || format!("robot kind {} (no description)", st.robot),
        described::title,
    );
    lines.push(Line::from(vec![
        label("robot"),
        Span::styled(format!("{title} · chassis/{}", s.name), bold(Color::White)),
        Span::raw(format!("  state #{}, {} old", st.seq, duration_text(age))),
    ]));
    if let Some(d) = s.description {
        lines.push(row("model", described::model_line(d)));
        lines.push(row("limits", described::limits_line(d)));
        if let Some(origin) = described::limits_origin_line(d) {
            lines.push(Line::from(vec![label(""), dim(origin)]));
        }
        if let Some(sensors) = described::sensors_line(d) {
            lines.push(row("sensors", sensors));
        }
        if let Some(joints) = described::joints_line(d) {
            lines.push(row("joints", joints));
        }
    }
    let mut flags = vec![Span::raw(
        ControlMode::name(st.system.control_mode).to_string(),
    )];
    let bad_link =
        st.link_flags & (LinkFlags::BUS_DOWN | LinkFlags::CHASSIS_SILENT | LinkFlags::RC_AUTHORITY);
    if bad_link != 0 {
        flags.push(Span::raw("  "));
        flags.push(Span::styled(
            LinkFlags::names(bad_link).join(", "),
            bold(Color::Red),
        ));
    }
    lines.push(Line::from([vec![label("mode")], flags].concat()));
    let faults = FaultFlags::names(st.system.fault_flags & !FaultFlags::WARNINGS);
    let warnings = FaultFlags::names(st.system.fault_flags & FaultFlags::WARNINGS);
    lines.push(Line::from(vec![
        label("faults"),
        if faults.is_empty() {
            Span::styled("none", Style::default().fg(Color::Green))
        } else {
            Span::styled(faults.join(", "), bold(Color::Red))
        },
        if warnings.is_empty() {
            Span::raw("")
        } else {
            Span::styled(
                format!("  warnings: {}", warnings.join(", ")),
                bold(Color::Yellow),
            )
        },
    ]));
    lines.push(row(
        "battery",
        described::battery_line(Some(st), s.description),
    ));
    lines.push(row(
        "speeds",
        format!(
            "{:+.3} m/s  {:+.3} rad/s  lateral {:+.3} m/s  steer {:+.1}°",
            st.motion.linear_mps,
            st.motion.angular_radps,
            st.motion.lateral_mps,
            st.motion.steer_rad.to_degrees()
        ),
    ));
    lines.push(row(
        "command",
        format!(
            "{:+.3} m/s  {:+.3} rad/s  steer {:+.1}° (on the wire)",
            st.command.linear_mps,
            st.command.angular_radps,
            st.command.steer_rad.to_degrees()
        ),
    ));
    lines.push(row(
        "pose",
        format!(
            "x {:.2} m  y {:.2} m  yaw {:.1}°",
            st.odometry.x_m,
            st.odometry.y_m,
            st.odometry.yaw_rad.to_degrees()
        ),
    ));
    lines
}

fn holder(mux: &MuxStatus, lock: &LockStatus) -> String {
    match lock.holder {
        LockStatus::HOLDER_OPERATOR => "operator".into(),
        LockStatus::HOLDER_NONE => "nobody".into(),
        i => mux
            .sources()
            .get(usize::from(i))
            .map_or_else(|| format!("source {i}"), |x| x.name().to_string()),
    }
}

fn mux_panel(s: &Snapshot) -> Vec<Line<'static>> {
    let mut lines = Vec::new();
    let Some(m) = s.mux else {
        lines.push(Line::from("no mux status yet"));
        return lines;
    };
    let active = match m.active() {
        Some(a) => Span::styled(
            format!(
                "active {} (priority {}, request {} ms old)",
                a.name(),
                a.priority,
                m.active_age_ms
            ),
            bold(Color::Green),
        ),
        None => Span::styled(format!("active none — {}", m.why()), bold(Color::Yellow)),
    };
    lines.push(Line::from(vec![label("decision"), active]));
    lines.push(row(
        "output",
        format!(
            "vx {:+.3}  vy {:+.3}  wz {:+.3}   requested vx {:+.3}  wz {:+.3}",
            m.output.linear_x_mps,
            m.output.linear_y_mps,
            m.output.angular_z_radps,
            m.requested.linear_x_mps,
            m.requested.angular_z_radps
        ),
    ));
    let clamps = ClampFlags::names(m.clamp_flags);
    lines.push(Line::from(vec![
        label("clamped"),
        if clamps.is_empty() {
            Span::raw("-")
        } else {
            Span::styled(clamps.join(", "), bold(Color::Yellow))
        },
        Span::raw(format!("   rejected requests {}", m.rejected_requests)),
    ]));
    lines.push(Line::from(dim(format!(
        "{:<10}{:<10}{:>4} {:>8} {:>9}  flags",
        "", "source", "prio", "timeout", "age"
    ))));
    for src in m.sources() {
        let mut flags = SourceFlags::names(src.flags);
        if !src.has(SourceFlags::FRESH) && src.age_ms != u32::MAX {
            flags.push("stale");
        }
        if src.rejected > 0 {
            flags.push("rejecting");
        }
        let style = if src.has(SourceFlags::ACTIVE) {
            bold(Color::Green)
        } else if src.has(SourceFlags::BLOCKED) || src.has(SourceFlags::LIMITING) {
            bold(Color::Yellow)
        } else {
            Style::default()
        };
        lines.push(Line::from(vec![
            label(""),
            Span::styled(
                format!(
                    "{:<10}{:>4} {:>8} {:>9}  {}",
                    src.name(),
                    src.priority,
                    format!("{} ms", src.timeout_ms),
                    src.age_text(),
                    flags.join(" ")
                ),
                style,
            ),
        ]));
    }
    for lock in m.locks() {
        let (text, style) = if lock.held != 0 {
            (
                format!(
                    "{} HELD by {} (blocks below {})",
                    lock.name(),
                    holder(m, lock),
                    lock.priority
                ),
                bold(Color::Red),
            )
        } else {
            (format!("{} free", lock.name()), Style::default())
        };
        lines.push(Line::from(vec![label("lock"), Span::styled(text, style)]));
    }
    lines
}

fn bus_panel(s: &Snapshot) -> Vec<Line<'static>> {
    let mut lines = Vec::new();
    if let Some(st) = s.state {
        let l = &st.link;
        let errors = l.rx_bad_checksum + l.rx_decode_errors + l.tx_errors;
        lines.push(Line::from(vec![
            label("link"),
            Span::raw(format!(
                "rx {} frames  tx {}  reconnects {}",
                l.rx_frames, l.tx_frames, l.bus_reconnects
            )),
        ]));
        lines.push(Line::from(vec![
            label("errors"),
            Span::styled(
                format!(
                    "bad checksums {}  decode errors {}  unknown ids {}  discarded bytes {}  tx errors {}",
                    l.rx_bad_checksum,
                    l.rx_decode_errors,
                    l.rx_unknown_id,
                    l.rx_bytes_discarded,
                    l.tx_errors
                ),
                if errors > 0 {
                    bold(Color::Yellow)
                } else {
                    Style::default()
                },
            ),
        ]));
        if l.can_state != ControllerState::UNKNOWN || l.can_error_frames > 0 {
            lines.push(Line::from(vec![
                label("can"),
                Span::styled(
                    format!(
                        "{}  tx/rx errors {}/{}  bus-off {}  restarts {}  error-passive {}  bus errors {}",
                        ControllerState::name(l.can_state),
                        l.can_tx_error_count,
                        l.can_rx_error_count,
                        l.can_bus_off,
                        l.can_restarts,
                        l.can_error_passive,
                        l.can_bus_errors
                    ),
                    match l.can_state {
                        ControllerState::BUS_OFF => bold(Color::Red),
                        ControllerState::ERROR_PASSIVE | ControllerState::ERROR_WARNING => {
                            bold(Color::Yellow)
                        }
                        _ => Style::default(),
                    },
                ),
            ]));
        }
    }
    lines.push(Line::from(vec![
        label("tap"),
        Span::styled(
            format!(
                "{} frames read, {} dropped (seq gaps)",
                s.bus.frames, s.bus.dropped
            ),
            if s.bus.dropped > 0 {
                bold(Color::Yellow)
            } else {
                Style::default()
            },
        ),
        if s.bus.serial_rejects > 0 {
            Span::raw(format!(
                ", {} serial candidates rejected",
                s.bus.serial_rejects
            ))
        } else {
            Span::raw("")
        },
    ]));
    let warming = s.running_ns < WINDOW_NS;
    lines.push(Line::from(dim(format!(
        "{:<4}{:<12}{:<20}{:>10}{:>10}{}",
        "",
        "id",
        "frame",
        "frames/s",
        "total",
        if warming {
            "   (first second: rates still filling)"
        } else {
            ""
        }
    ))));
    for k in s.bus.keys() {
        lines.push(Line::from(vec![
            Span::styled(
                format!("{:<4}", FrameDirection::name(k.direction).to_uppercase()),
                if k.direction == FrameDirection::TX {
                    bold(Color::Magenta)
                } else {
                    bold(Color::Cyan)
                },
            ),
            Span::raw(format!(
                "{:<12}{:<20}{:>10.0}{:>10}",
                k.key.text(),
                k.name.as_deref().unwrap_or("?"),
                k.rate_hz(),
                k.total
            )),
        ]));
    }
    lines
}

/// A row of percentiles; values below `resolution_ns` (the figure's resolution) read `<1 ms`.
fn latency_row(
    name: &str,
    samples: &Samples,
    resolution_ns: u64,
    meaning: &str,
) -> Vec<Line<'static>> {
    let show = |ns: u64| {
        if ns < resolution_ns {
            format!("<{}", duration_text(resolution_ns))
        } else {
            duration_text(ns)
        }
    };
    let figures = match samples.summary() {
        Some(x) => format!(
            "{:>10}{:>10}{:>10}{:>8}",
            show(x.p50_ns),
            show(x.p99_ns),
            show(x.max_ns),
            x.count
        ),
        None => format!("{:>38}", "no samples yet"),
    };
    vec![
        Line::from(vec![
            Span::styled(format!("{name:<18}"), bold(Color::White)),
            Span::raw(figures),
        ]),
        Line::from(dim(format!("  {meaning}"))),
    ]
}

fn latency_panel(s: &Snapshot) -> Vec<Line<'static>> {
    let l = s.latency;
    let mut lines = vec![Line::from(dim(format!(
        "{:<18}{:>10}{:>10}{:>10}{:>8}",
        "", "p50", "p99", "max", "n"
    )))];
    lines.extend(latency_row(
        "frame→state",
        &l.frame_to_state,
        0,
        "chassisd read a frame → this process woke with the state it changed",
    ));
    lines.extend(latency_row(
        "state age",
        &l.state_age,
        0,
        "age of every state sample on arrival (refreshes: up to a 20 ms tick more)",
    ));
    lines.extend(latency_row(
        "decision→wire",
        &l.decision_to_wire,
        0,
        "mux output changed → first motion frame written (chassisd's stamps)",
    ));
    lines.extend(latency_row(
        "request→decision",
        &l.request_to_decision,
        1_000_000,
        "winner's new request (stamp) → the decision taking it in (whole ms, from the mux)",
    ));
    if l.unmatched > 0 {
        lines.push(Line::from(dim(format!(
            "  {} output changes had no motion frame within 500 ms (tap drops?)",
            l.unmatched
        ))));
    }
    lines.push(Line::from(dim(format!(
        "all CLOCK_MONOTONIC; percentiles over the last {} samples",
        super::stats::SAMPLES
    ))));
    lines
}

fn plain(line: &Line) -> String {
    line.spans.iter().map(|s| s.content.as_ref()).collect()
}

/// The snapshot as plain text, one panel after another.
pub fn text(s: &Snapshot) -> String {
    let mut out = String::new();
    for panel in panels(s) {
        out.push_str(&format!("== {} ==\n", panel.title));
        for line in &panel.lines {
            out.push_str(plain(line).trim_end());
            out.push('\n');
        }
    }
    out
}

/// Draws the dashboard.
pub fn render(frame: &mut Frame, s: &Snapshot) {
    let [robot, mux, bus, latency] = panels(s);
    let height = |p: &Panel| {
        u16::try_from(p.lines.len())
            .unwrap_or(u16::MAX)
            .saturating_add(2)
    };
    let top_height = height(&robot).max(height(&mux));
    let [top, bottom, help] = Layout::vertical([
        Constraint::Length(top_height),
        Constraint::Min(6),
        Constraint::Length(1),
    ])
    .areas(frame.area());
    let [left, right] =
        Layout::horizontal([Constraint::Percentage(45), Constraint::Percentage(55)]).areas(top);
    let [bus_area, latency_area] =
        Layout::horizontal([Constraint::Percentage(50), Constraint::Percentage(50)]).areas(bottom);
    for (panel, area) in [
        (robot, left),
        (mux, right),
        (bus, bus_area),
        (latency, latency_area),
    ] {
        frame.render_widget(
            Paragraph::new(panel.lines)
                .block(Block::bordered().title(format!(" {} ", panel.title))),
            area,
        );
    }
    frame.render_widget(
        Paragraph::new(Line::from(vec![
            Span::styled(
                format!(" chassis top — chassis/{} ", s.name),
                bold(Color::White),
            ),
            dim("q quit".into()),
        ])),
        help,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::{BusFrame, FrameKind};
    use chassis_protocols::RobotKind;
    use chassis_protocols::description::describe;
    use ratatui::Terminal;
    use ratatui::backend::TestBackend;

    fn titan() -> RobotDescription {
        let mut d = describe(&RobotKind::Titan.entry().defaults());
        d.configured_limits.forward_mps = 1.2;
        d
    }

    fn snapshot_parts() -> (ChassisState, MuxStatus, BusStats, Latency) {
        let mut state = ChassisState {
            robot: RobotKind::Titan.id(),
            seq: 7,
            stamp_ns: 5_000_000_000,
            ..ChassisState::default()
        };
        state.system.battery_voltage_v = 51.9;
        state.link.rx_bad_checksum = 3;
        let mut mux = MuxStatus {
            source_count: 2,
            lock_count: 1,
            active_source: 1,
            active_age_ms: 4,
            ..MuxStatus::default()
        };
        mux.sources[0].set_name("safety");
        mux.sources[0].priority = 255;
        mux.sources[0].age_ms = u32::MAX;
        mux.sources[1].set_name("teleop");
        mux.sources[1].priority = 100;
        mux.sources[1].flags = SourceFlags::ACTIVE | SourceFlags::FRESH;
        mux.locks[0].set_name("estop");
        let mut bus = BusStats::new(Some(&RobotKind::Titan.entry().defaults()));
        for i in 0..50u64 {
            let mut f = BusFrame {
                seq: i + 1,
                stamp_ns: 4_010_000_000 + i * 20_000_000,
                can_id: 0x211,
                kind: FrameKind::CAN,
                ..BusFrame::default()
            };
            f.set_payload(&[0; 8]);
            bus.on_frame(&f);
        }
        bus.expire(5_000_000_000);
        let mut latency = Latency::default();
        latency.on_state(5_000_300_000, &state, true);
        (state, mux, bus, latency)
    }

    /// Calls `check` with the TITAN's snapshot at 5 s: 2 s running, teleop active, 0x211 at
    /// 50 Hz, state 300 µs old.
    fn with_snapshot<R>(check: impl FnOnce(&Snapshot) -> R) -> R {
        let (state, mux, bus, latency) = snapshot_parts();
        let description = titan();
        let s = Snapshot {
            name: "titan",
            now_ns: 5_000_000_000,
            running_ns: 2_000_000_000,
            description: Some(&description),
            state: Some(&state),
            mux: Some(&mux),
            bus: &bus,
            latency: &latency,
        };
        check(&s)
    }

    #[test]
    fn the_text_snapshot_shows_rates_per_id_the_active_source_and_latency() {
        let text = with_snapshot(text);
        assert!(text.contains("RX  0x211"), "{text}");
        assert!(text.contains("system_status"), "{text}");
        assert!(text.contains("active teleop (priority 100"), "{text}");
        assert!(text.contains("bad checksums 3"), "{text}");
        assert!(text.contains("estop free"), "{text}");
        assert!(
            text.contains("AgileX TITAN (titan) · chassis/titan"),
            "{text}"
        );
        assert!(
            text.contains("limits    forward 1.20 · reverse 3.00 m/s"),
            "{text}"
        );
        assert!(text.contains("[mux.limits] forward 1.20"), "{text}");
        assert!(text.contains("levels: low 45.0 V / 15 %"), "{text}");
        assert!(
            text.contains("joints    front_steer_joint, rear_steer_joint"),
            "{text}"
        );
        assert!(text.contains("state age"), "{text}");
        assert!(text.contains("300 µs"), "{text}");
        let rate_line = text.lines().find(|l| l.contains("0x211")).unwrap();
        assert!(rate_line.contains(" 50 "), "{rate_line}");
    }

    #[test]
    fn the_dashboard_renders_every_panel() {
        let mut terminal = Terminal::new(TestBackend::new(160, 40)).unwrap();
        with_snapshot(|s| {
            terminal.draw(|f| render(f, s)).unwrap();
        });
        let buffer = terminal.backend().buffer();
        let screen: String = buffer.content.iter().map(|c| c.symbol()).collect();
        for needle in [" robot ", " mux ", " bus ", " latency ", "0x211", "teleop"] {
            assert!(screen.contains(needle), "{needle} missing");
        }
    }

    #[test]
    fn durations_are_shown_in_a_readable_unit() {
        assert_eq!(duration_text(850_000), "850 µs");
        assert_eq!(duration_text(12_345_678), "12.3 ms");
        assert_eq!(duration_text(1_200_000_000), "1.20 s");
        let mut s = Samples::default();
        s.push(0);
        let row = plain(&latency_row("x", &s, 1_000_000, "")[0]);
        assert!(row.contains("<1.0 ms"), "{row}");
    }
}
