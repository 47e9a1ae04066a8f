//! What the operator sees: a view model (the robot's state, the mux's decision, the keyboard)
//! and a render function from it. Pure: tests render into ratatui's `TestBackend`.

use chassis_client::{
    ChassisState, ClampFlags, ControlMode, FaultFlags, Group, Kinematics, LinkFlags, LockStatus,
    MuxStatus, RobotDescription, SourceFlags, WireProtocol, ZeroReason,
};
use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Padding, Paragraph, Wrap};

use crate::keys::{Command, Held, Limits, Motion};

/// A state older than this is shown as stale.
const STALE_NS: u64 = 500_000_000;
/// A mux status older than this is shown as stale.
const MUX_STALE_NS: u64 = 1_000_000_000;

/// How the keyboard reports releases.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Releases {
    /// The terminal sends release events (kitty keyboard protocol).
    Reported,
    /// Releases are inferred from auto-repeat.
    Inferred,
}

/// The keyboard side of the screen.
#[derive(Debug, Clone, PartialEq)]
pub struct KeysView {
    pub held: Held,
    pub level: u32,
    pub max_level: u32,
    /// The robot's effective limits the steps stop at.
    pub limits: Limits,
    /// Speeds of the current step.
    pub linear_mps: f32,
    pub angular_radps: f32,
    /// What is being published (meaningful while `driving`).
    pub command: Command,
    pub driving: bool,
    pub releases: Releases,
    pub first_hold_ms: u64,
    pub repeat_hold_ms: u64,
}

/// Everything one screen shows.
#[derive(Debug, Clone)]
pub struct View<'a> {
    pub robot: &'a str,
    pub source: &'a str,
    pub now_ns: u64,
    /// What chassisd says the robot is (`None`: not yet, or an older chassisd).
    pub description: Option<&'a RobotDescription>,
    pub state: Option<&'a ChassisState>,
    pub mux: Option<&'a MuxStatus>,
    pub keys: KeysView,
    /// The last thing worth telling the operator (an e-stop without a lock, an error).
    pub message: Option<&'a str>,
}

/// Who has the robot, from the operator's point of view.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Authority {
    /// No mux status yet.
    Unknown,
    /// Our source is the winner.
    Ours,
    /// Someone overrides us: a higher-priority source, a lock, a stale safety monitor, a
    /// safety envelope clamping us — or our keys are held but another source wins.
    Override { by: String, why: String },
    /// We ask for nothing; the mux's choice, for information.
    Other { active: Option<String>, why: String },
}

/// Decides [`Authority`] from the mux status, our source's name and whether keys are held.
pub fn authority(mux: Option<&MuxStatus>, source: &str, driving: bool) -> Authority {
    let Some(mux) = mux else {
        return Authority::Unknown;
    };
    let ours = mux.sources().iter().find(|s| s.name() == source);
    let our_priority = ours.map_or(0, |s| s.priority);
    if let Some(lock) = mux.locks().iter().find(|l| l.held != 0)
        && ours.is_some_and(|s| s.has(SourceFlags::BLOCKED))
    {
        return Authority::Override {
            by: format!("lock {}", lock.name()),
            why: format!("held by {}", lock_holder(mux, lock)),
        };
    }
    match mux.active() {
        Some(active) if active.name() == source => {
            if mux.clamp_flags & ClampFlags::SAFETY_LIMIT != 0 {
                let limiter = mux
                    .sources()
                    .iter()
                    .find(|s| s.has(SourceFlags::LIMITING))
                    .map_or("a limiting source".to_string(), |s| s.name().to_string());
                Authority::Override {
                    by: limiter,
                    why: "speed envelope clamps us".into(),
                }
            } else {
                Authority::Ours
            }
        }
        Some(active) if active.priority > our_priority || driving => Authority::Override {
            by: active.name().to_string(),
            why: format!("priority {} is in control", active.priority),
        },
        Some(active) => Authority::Other {
            active: Some(active.name().to_string()),
            why: format!("priority {}", active.priority),
        },
        None if driving => Authority::Override {
            by: match mux.zero_reason {
                ZeroReason::REQUIRED_SOURCE_STALE => "no safety monitor".to_string(),
                ZeroReason::LOCKED => "a lock".to_string(),
                ZeroReason::AWAITING_ZERO => "motion only from a zero".to_string(),
                ZeroReason::HELD => "the chassis".to_string(),
                _ => "the mux".to_string(),
            },
            why: mux.why().to_string(),
        },
        None => Authority::Other {
            active: None,
            why: mux.why().to_string(),
        },
    }
}

fn lock_holder(mux: &MuxStatus, lock: &LockStatus) -> String {
    match lock.holder {
        LockStatus::HOLDER_OPERATOR => "the operator".to_string(),
        LockStatus::HOLDER_NONE => "nobody".to_string(),
        i => mux
            .sources()
            .get(usize::from(i))
            .map_or_else(|| format!("source {i}"), |s| s.name().to_string()),
    }
}

fn bold(color: Color) -> Style {
    Style::default().fg(color).add_modifier(Modifier::BOLD)
}

fn label(text: &str) -> Span<'static> {
    Span::styled(format!("{text:<10}"), Style::default().fg(Color::DarkGray))
}

/// Draws the whole screen.
pub fn render(frame: &mut Frame, view: &View) {
    let latched = (view.mux)
        .and_then(|m| m.locks().iter().find(|l| l.name() == "estop"))
        .is_some_and(|l| l.held != 0);
    let [top, middle, banner, help] = Layout::vertical([
        Constraint::Length(4),
        Constraint::Min(9),
        Constraint::Length(if latched || view.message.is_some() {
            2
        } else {
            0
        }),
        Constraint::Length(1),
    ])
    .areas(frame.area());
    render_keys(frame, top, view);
    let [left, right] =
        Layout::horizontal([Constraint::Percentage(50), Constraint::Percentage(50)]).areas(middle);
    render_mux(frame, left, view);
    render_robot(frame, right, view);
    let mut lines = Vec::new();
    if latched {
        lines.push(Line::from(Span::styled(
            "E-STOP LATCHED — release with `chassis control estop-release`",
            bold(Color::White).bg(Color::Red),
        )));
    }
    if let Some(message) = view.message {
        lines.push(Line::from(Span::styled(
            message.to_string(),
            bold(Color::Yellow),
        )));
    }
    frame.render_widget(Paragraph::new(lines), banner);
    frame.render_widget(
        Paragraph::new(Line::from(vec![
            Span::styled("↑↓←→/WASD", bold(Color::Cyan)),
            Span::raw(" drive (hold)  "),
            Span::styled("+/-", bold(Color::Cyan)),
            Span::raw(" speed  "),
            Span::styled("space", bold(Color::Cyan)),
            Span::raw(" stop  "),
            Span::styled("e", bold(Color::Cyan)),
            Span::raw(" e-stop  "),
            Span::styled("q", bold(Color::Cyan)),
            Span::raw(" quit"),
        ])),
        help,
    );
}

fn arrows(held: Held) -> String {
    let glyph = |m: Motion, g: &'static str| if held.contains(m) { g } else { "·" };
    format!(
        "{}{}{}{}",
        glyph(Motion::Forward, "↑"),
        glyph(Motion::Reverse, "↓"),
        glyph(Motion::Left, "←"),
        glyph(Motion::Right, "→")
    )
}

fn render_keys(frame: &mut Frame, area: Rect, view: &View) {
    let k = &view.keys;
    let status = if k.driving {
        Span::styled(
            format!(
                " DRIVING {} v {:+.2} m/s  ω {:+.2} rad/s ",
                arrows(k.held),
                k.command.linear_mps,
                k.command.angular_radps
            ),
            bold(Color::Black).bg(Color::Green),
        )
    } else {
        Span::styled(
            " idle — publishing nothing ".to_string(),
            Style::default().fg(Color::Gray),
        )
    };
    let releases = match k.releases {
        Releases::Reported => format!(
            "key releases: reported by the terminal (a key that stops repeating still ends after {} ms)",
            k.repeat_hold_ms
        ),
        Releases::Inferred => format!(
            "key releases: inferred (hold {} ms, then {} ms per repeat)",
            k.first_hold_ms, k.repeat_hold_ms
        ),
    };
    let lines = vec![
        Line::from(vec![
            status,
            Span::raw(format!(
                "  step {}/{}: {:.2} m/s, {:.2} rad/s",
                k.level, k.max_level, k.linear_mps, k.angular_radps
            )),
            Span::styled(limits_text(&k.limits), Style::default().fg(Color::DarkGray)),
        ]),
        Line::from(Span::styled(releases, Style::default().fg(Color::DarkGray))),
    ];
    let title = format!(
        " chassis-teleop — chassis/{} — source {} ",
        view.robot, view.source
    );
    frame.render_widget(
        Paragraph::new(lines).block(
            Block::bordered()
                .padding(Padding::horizontal(1))
                .title(title),
        ),
        area,
    );
}

/// `  robot: ≤ 1.50 m/s forward, 1.00 reverse, 0.52 rad/s` (the limits known).
fn limits_text(l: &Limits) -> String {
    let mut words = Vec::new();
    if l.forward_mps.is_finite() {
        words.push(format!("≤ {:.2} m/s forward", l.forward_mps));
    }
    if l.reverse_mps.is_finite() {
        words.push(format!("{:.2} reverse", l.reverse_mps));
    }
    if l.angular_radps.is_finite() {
        words.push(format!("{:.2} rad/s", l.angular_radps));
    }
    if words.is_empty() {
        String::new()
    } else {
        format!("  robot: {}", words.join(", "))
    }
}

/// The robot as described: `AgileX TITAN (titan)`, its kinematics and protocol in use.
fn robot_lines(d: &RobotDescription) -> Vec<Line<'static>> {
    let title = match (d.display_name(), d.kind_name()) {
        ("", kind) => kind.to_string(),
        (display, kind) => format!("{display} ({kind})"),
    };
    let mut lines = vec![Line::from(vec![
        label("robot"),
        Span::styled(title, bold(Color::White)),
    ])];
    let mut words = vec![
        Kinematics::name(d.kinematics).to_string(),
        format!("protocol {}", WireProtocol::name(d.protocol)),
    ];
    if d.model() != d.kind_name() {
        words.insert(0, d.model().to_string());
    }
    lines.push(Line::from(vec![
        label("drive"),
        Span::raw(words.join(" · ")),
    ]));
    if Kinematics::steers(d.kinematics) {
        lines.push(Line::from(vec![
            label("turning"),
            Span::raw("only while moving (steered wheels)"),
        ]));
    }
    lines
}

fn render_mux(frame: &mut Frame, area: Rect, view: &View) {
    let mut lines = Vec::new();
    if let Some(mux) = view.mux {
        // Published at 10 Hz at least: older means chassisd is gone or stuck.
        let age_ns = view.now_ns.saturating_sub(mux.stamp_ns);
        if age_ns > MUX_STALE_NS {
            lines.push(Line::from(Span::styled(
                format!("MUX STATUS STALE: {:.1} s old", age_ns as f64 / 1e9),
                bold(Color::White).bg(Color::Red),
            )));
        }
    }
    match authority(view.mux, view.source, view.keys.driving) {
        Authority::Unknown => lines.push(Line::from("waiting for the mux…")),
        Authority::Ours => lines.push(Line::from(vec![
            label("active"),
            Span::styled(
                format!(" {} ", view.source),
                bold(Color::Black).bg(Color::Green),
            ),
            Span::raw(" (us)"),
        ])),
        Authority::Override { by, why } => {
            lines.push(Line::from(vec![
                label("active"),
                Span::styled(
                    format!(" SAFETY OVERRIDE: {by} "),
                    bold(Color::White).bg(Color::Red),
                ),
            ]));
            lines.push(Line::from(vec![label(""), Span::raw(why)]));
        }
        Authority::Other { active, why } => lines.push(Line::from(vec![
            label("active"),
            Span::styled(active.unwrap_or_else(|| "none".into()), bold(Color::Yellow)),
            Span::raw(format!(" ({why})")),
        ])),
    }
    if let Some(mux) = view.mux {
        lines.push(Line::from(vec![
            label("output"),
            Span::raw(format!(
                "vx {:+.2}  vy {:+.2}  wz {:+.2}",
                mux.output.linear_x_mps, mux.output.linear_y_mps, mux.output.angular_z_radps
            )),
        ]));
        let clamps = ClampFlags::names(mux.clamp_flags);
        lines.push(Line::from(vec![
            label("clamped"),
            if clamps.is_empty() {
                Span::raw("-")
            } else {
                Span::styled(clamps.join(", "), bold(Color::Yellow))
            },
        ]));
        for s in mux.sources() {
            let mut words = vec![format!(
                "{:<8} {:>3}  {:>8}",
                s.name(),
                s.priority,
                s.age_text()
            )];
            words.extend(SourceFlags::names(s.flags).into_iter().map(String::from));
            let style = if s.has(SourceFlags::ACTIVE) {
                bold(Color::Green)
            } else {
                Style::default()
            };
            lines.push(Line::from(vec![
                label("source"),
                Span::styled(words.join(" "), style),
            ]));
        }
        for l in mux.locks() {
            let (text, style) = if l.held != 0 {
                (
                    format!("{} HELD by {}", l.name(), lock_holder(mux, l)),
                    bold(Color::Red),
                )
            } else {
                (format!("{} free", l.name()), Style::default())
            };
            lines.push(Line::from(vec![label("lock"), Span::styled(text, style)]));
        }
    }
    render_wrapped(frame, area, " mux ", lines);
}

/// A bordered panel whose long lines wrap.
fn render_wrapped(frame: &mut Frame, area: Rect, title: &str, lines: Vec<Line<'_>>) {
    frame.render_widget(
        Paragraph::new(lines).wrap(Wrap { trim: false }).block(
            Block::bordered()
                .padding(Padding::horizontal(1))
                .title(title),
        ),
        area,
    );
}

fn render_robot(frame: &mut Frame, area: Rect, view: &View) {
    let mut lines = view.description.map(robot_lines).unwrap_or_default();
    match view.state {
        None => lines.push(Line::from("waiting for the robot's state…")),
        Some(s) => {
            let age_ns = view.now_ns.saturating_sub(s.stamp_ns);
            if age_ns > STALE_NS {
                lines.push(Line::from(Span::styled(
                    format!("STATE STALE: {:.1} s old", age_ns as f64 / 1e9),
                    bold(Color::White).bg(Color::Red),
                )));
            }
            lines.push(Line::from(vec![
                label("speed"),
                Span::styled(
                    format!("{:+.2} m/s", s.motion.linear_mps),
                    bold(Color::White),
                ),
                Span::raw(format!("  yaw {:+.2} rad/s", s.motion.angular_radps)),
            ]));
            lines.push(Line::from(vec![
                label("steering"),
                Span::raw(format!(
                    "{:+.1}°  (front {:+.1}°, rear {:+.1}°)",
                    s.motion.steer_rad.to_degrees(),
                    s.motion.front_steer_rad.to_degrees(),
                    s.motion.rear_steer_rad.to_degrees()
                )),
            ]));
            let soc = if s.is_valid(Group::BmsPack) {
                format!("  {:.0} %", s.system.battery_soc_pct)
            } else {
                String::new()
            };
            let low = s.system.fault_flags
                & (FaultFlags::BATTERY_LOW
                    | FaultFlags::BATTERY_UNDER_VOLTAGE
                    | FaultFlags::BATTERY_UNDER_VOLTAGE_WARNING)
                != 0;
            let level = view
                .description
                .map(|d| (d.battery.low_v, d.battery.low_soc_pct))
                .map_or(String::new(), |(v, pct)| {
                    match (v.is_finite(), pct.is_finite()) {
                        (_, true) => format!("  (low below {pct:.0} %)"),
                        (true, false) => format!("  (low below {v:.1} V)"),
                        _ => String::new(),
                    }
                });
            lines.push(Line::from(vec![
                label("battery"),
                Span::styled(
                    format!("{:.1} V{soc}{level}", s.system.battery_voltage_v),
                    if low {
                        bold(Color::Red)
                    } else {
                        Style::default()
                    },
                ),
            ]));
            lines.push(Line::from(vec![
                label("mode"),
                Span::raw(ControlMode::name(s.system.control_mode)),
            ]));
            let faults = FaultFlags::names(s.system.fault_flags & !FaultFlags::WARNINGS);
            let warnings = FaultFlags::names(s.system.fault_flags & FaultFlags::WARNINGS);
            lines.push(Line::from(vec![
                label("faults"),
                if faults.is_empty() {
                    Span::styled("none", Style::default().fg(Color::Green))
                } else {
                    Span::styled(faults.join(", "), bold(Color::Red))
                },
            ]));
            if !warnings.is_empty() {
                lines.push(Line::from(vec![
                    label("warnings"),
                    Span::styled(warnings.join(", "), bold(Color::Yellow)),
                ]));
            }
            let link = LinkFlags::names(
                s.link_flags
                    & (LinkFlags::BUS_DOWN | LinkFlags::CHASSIS_SILENT | LinkFlags::RC_AUTHORITY),
            );
            if !link.is_empty() {
                lines.push(Line::from(vec![
                    label("link"),
                    Span::styled(link.join(", "), bold(Color::Red)),
                ]));
            }
        }
    }
    render_wrapped(frame, area, " robot ", lines);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::keys::{Settings, Teleop};
    use chassis_client::Stop;
    use chassis_protocols::RobotKind;
    use chassis_protocols::description::describe;
    use ratatui::Terminal;
    use ratatui::backend::TestBackend;

    fn mux(active: &str) -> MuxStatus {
        let mut m = MuxStatus {
            source_count: 3,
            lock_count: 1,
            active_source: MuxStatus::NO_SOURCE,
            stamp_ns: 1_000_000_000,
            ..MuxStatus::default()
        };
        for (i, (name, priority)) in [("safety", 255), ("teleop", 100), ("planner", 10)]
            .into_iter()
            .enumerate()
        {
            m.sources[i].set_name(name);
            m.sources[i].priority = priority;
            m.sources[i].age_ms = u32::MAX;
            if name == active {
                m.active_source = i as u8;
                m.sources[i].flags = SourceFlags::ACTIVE | SourceFlags::FRESH;
                m.sources[i].age_ms = 12;
            }
        }
        if m.active().is_none() {
            m.zero_reason = ZeroReason::NO_ACTIVE_SOURCE;
        }
        m.locks[0].set_name("estop");
        m.locks[0].priority = 255;
        m.locks[0].holder = LockStatus::HOLDER_NONE;
        m
    }

    fn state() -> ChassisState {
        let mut s = ChassisState {
            stamp_ns: 1_000_000_000,
            ..ChassisState::default()
        };
        s.motion.linear_mps = 0.42;
        s.system.battery_voltage_v = 51.3;
        s.system.control_mode = ControlMode::COMMAND;
        s
    }

    /// The TITAN seen by our `teleop` source, without a description or a message.
    fn titan_view<'a>(
        now_ns: u64,
        state: Option<&'a ChassisState>,
        mux: &'a MuxStatus,
        driving: bool,
    ) -> View<'a> {
        View {
            robot: "titan",
            source: "teleop",
            now_ns,
            description: None,
            state,
            mux: Some(mux),
            keys: keys(driving),
            message: None,
        }
    }

    fn keys(driving: bool) -> KeysView {
        let command = Command {
            linear_mps: if driving { 0.1 } else { 0.0 },
            angular_radps: 0.0,
        };
        KeysView {
            held: Held::default(),
            level: 1,
            max_level: 10,
            limits: Limits::NONE,
            linear_mps: 0.1,
            angular_radps: 0.2,
            command,
            driving,
            releases: Releases::Inferred,
            first_hold_ms: 700,
            repeat_hold_ms: 200,
        }
    }

    fn screen(view: &View) -> String {
        let mut terminal = Terminal::new(TestBackend::new(120, 30)).unwrap();
        terminal.draw(|f| render(f, view)).unwrap();
        let buffer = terminal.backend().buffer();
        let width = usize::from(buffer.area.width);
        buffer
            .content
            .chunks(width)
            .map(|row| row.iter().map(|c| c.symbol()).collect::<String>())
            .collect::<Vec<_>>()
            .join("\n")
    }

    #[test]
    fn the_screen_shows_our_source_in_control_speed_battery_and_faults() {
        let mux = mux("teleop");
        let mut state = state();
        state.system.fault_flags = FaultFlags::MOTOR_DRIVER_ERROR | FaultFlags::BATTERY_LOW;
        let view = titan_view(1_100_000_000, Some(&state), &mux, true);
        let text = screen(&view);
        assert!(text.contains("active     teleop"), "{text}");
        assert!(text.contains("DRIVING"), "{text}");
        assert!(text.contains("+0.42 m/s"), "{text}");
        assert!(text.contains("51.3 V"), "{text}");
        assert!(text.contains("motor_driver_error"), "{text}");
        assert!(text.contains("battery_low"), "{text}");
        assert!(!text.contains("SAFETY"), "{text}");
        assert!(!text.contains("STALE"), "{text}");
        assert!(!text.contains("E-STOP"), "{text}");
    }

    #[test]
    fn every_robot_is_shown_as_described_with_the_limits_its_steps_stop_at() {
        let mux = mux("teleop");
        let state = state();
        for kind in RobotKind::ALL {
            let mut d = describe(&kind.entry().defaults());
            // chassisd's `[mux.limits] max_linear_mps = 0.45`.
            d.configured_limits.forward_mps = 0.45;
            d.configured_limits.reverse_mps = 0.45;
            let mut teleop = Teleop::new(Settings::default());
            teleop.set_limits(Limits::of(&d));
            let mut keys = keys(false);
            keys.limits = teleop.limits();
            keys.max_level = teleop.max_level();
            let view = View {
                robot: kind.name(),
                source: "teleop",
                now_ns: 1_000_000_000,
                description: Some(&d),
                state: Some(&state),
                mux: Some(&mux),
                keys,
                message: None,
            };
            let text = screen(&view);
            let title = format!("{} ({})", kind.entry().display_name, kind.name());
            assert!(text.contains(&title), "{kind}: {text}");
            assert!(
                text.contains("robot: ≤ 0.45 m/s forward, 0.45 reverse"),
                "{text}"
            );
            assert_eq!(
                text.contains("only while moving (steered wheels)"),
                Kinematics::steers(d.kinematics),
                "{kind}: {text}"
            );
            assert!(text.contains("(low below"), "{kind}: {text}");
        }
    }

    #[test]
    fn a_higher_priority_winner_is_highlighted_as_a_safety_override() {
        let mux = mux("safety");
        let state = state();
        let view = titan_view(1_000_000_000, Some(&state), &mux, true);
        let text = screen(&view);
        assert!(text.contains("SAFETY OVERRIDE: safety"), "{text}");
        // The highlight is red.
        let mut terminal = Terminal::new(TestBackend::new(120, 30)).unwrap();
        terminal.draw(|f| render(f, &view)).unwrap();
        let buffer = terminal.backend().buffer();
        let red = buffer
            .content
            .iter()
            .filter(|c| c.bg == Color::Red)
            .map(|c| c.symbol())
            .collect::<String>();
        assert!(red.contains("SAFETY OVERRIDE"), "{red}");
    }

    #[test]
    fn a_lower_priority_winner_is_only_information_while_we_are_idle() {
        let mux = mux("planner");
        let view = titan_view(0, None, &mux, false);
        let text = screen(&view);
        assert!(text.contains("active    planner (priority 10)"), "{text}");
        assert!(!text.contains("SAFETY"), "{text}");
        assert!(text.contains("idle"), "{text}");
        assert!(text.contains("waiting for the robot"), "{text}");
        // While our keys are held, the same winner is an override.
        assert!(matches!(
            authority(Some(&mux), "teleop", true),
            Authority::Override { .. }
        ));
    }

    #[test]
    fn a_latched_estop_is_shown_with_how_to_release_it() {
        let mut mux = mux("none");
        mux.locks[0].held = 1;
        mux.locks[0].holder = 1;
        mux.zero_reason = ZeroReason::LOCKED;
        mux.sources[1].flags |= SourceFlags::BLOCKED;
        mux.sources[2].flags |= SourceFlags::BLOCKED;
        let state = state();
        let view = titan_view(3_000_000_000, Some(&state), &mux, false);
        let text = screen(&view);
        assert!(
            text.contains("E-STOP LATCHED — release with `chassis control estop-release`"),
            "{text}"
        );
        assert!(text.contains("estop HELD by teleop"), "{text}");
        assert!(text.contains("SAFETY OVERRIDE: lock estop"), "{text}");
        assert!(text.contains("STATE STALE"), "{text}");
        assert!(text.contains("MUX STATUS STALE: 2.0 s old"), "{text}");
    }

    #[test]
    fn a_stale_safety_monitor_while_driving_is_an_override() {
        let mut mux = mux("none");
        mux.zero_reason = ZeroReason::REQUIRED_SOURCE_STALE;
        mux.sources[0].flags = SourceFlags::REQUIRED;
        assert_eq!(
            authority(Some(&mux), "teleop", true),
            Authority::Override {
                by: "no safety monitor".into(),
                why: "stopped: required source safety silent".into()
            }
        );
        mux.zero_reason = ZeroReason::AWAITING_ZERO;
        mux.awaiting_source = 1;
        mux.stop = Stop::REQUIRED_SOURCE;
        assert_eq!(
            authority(Some(&mux), "teleop", true),
            Authority::Override {
                by: "motion only from a zero".into(),
                why: "stopped: waiting for a zero from teleop since the required source came \
                      back"
                    .into()
            }
        );
        assert_eq!(authority(None, "teleop", true), Authority::Unknown);
    }

    #[test]
    fn a_safety_envelope_clamping_us_is_an_override() {
        let mut mux = mux("teleop");
        mux.clamp_flags = ClampFlags::SAFETY_LIMIT;
        mux.sources[0].flags = SourceFlags::LIMITING | SourceFlags::FRESH;
        assert_eq!(
            authority(Some(&mux), "teleop", true),
            Authority::Override {
                by: "safety".into(),
                why: "speed envelope clamps us".into()
            }
        );
    }
}
