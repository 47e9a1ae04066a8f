//! The loop: the terminal, the robot and the keyboard state machine.
//!
//! One thread. It waits in crossterm's `event::poll` with a timeout up to the next 50 ms screen
//! tick or the keyboard's next deadline (a hold lapsing, the command due again), so keys are
//! handled the moment they arrive and nothing sleeps. Every tick reads the newest state and mux
//! decision and redraws (ratatui sends only the cells that changed, which keeps it light over
//! SSH).
//!
//! The robot's description (`chassis/<name>/robot`) is read at start and again whenever chassisd
//! publishes a newer one: the screen shows what the robot is, and the speed steps stop at its
//! effective limits ([`keys::Limits`]).
//!
//! Stopping: a focus loss or a lapsed hold sends one stop (see [`crate::keys`]); quitting, an
//! error or a panic stops the robot if we were moving it ([`Outlet`]'s `Drop`), and the terminal
//! is restored in every case ([`Screen`]'s `Drop`, plus a panic hook). A hung-up SSH session
//! kills the process (SIGHUP): the mux's timeout of our source (300 ms by default) stops the
//! robot then.

use std::io::{Stdout, Write, stdout};
use std::sync::Once;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use chassis_client::{
    ChassisState, ClientError, MuxStatus, Robot, RobotDescription, Source, VelocityRequest,
    install_signal_handlers, now_ns, termination_requested,
};
use crossterm::event::{
    self, DisableFocusChange, EnableFocusChange, Event, KeyboardEnhancementFlags,
    PopKeyboardEnhancementFlags, PushKeyboardEnhancementFlags,
};
use crossterm::terminal::{
    EnterAlternateScreen, LeaveAlternateScreen, disable_raw_mode, enable_raw_mode,
    supports_keyboard_enhancement,
};
use crossterm::{cursor, execute};
use ratatui::Terminal;
use ratatui::backend::CrosstermBackend;

use crate::keys::{self, Action, Settings, Teleop};
use crate::view::{self, KeysView, Releases, View};

/// The screen's refresh period.
const TICK_NS: u64 = 50_000_000;
/// How often to check that chassisd still serves the robot while its state is stale.
const SERVED_CHECK_NS: u64 = 1_000_000_000;
/// Longest wait at start for the robot's description (chassisd hands it to a new reader within
/// a tick of its loop).
const DESCRIPTION_WAIT: Duration = Duration::from_millis(500);

/// What `chassis-teleop` was asked to do.
#[derive(Debug, Clone)]
pub struct Options {
    pub name: String,
    pub source: String,
    pub settings: Settings,
}

/// Connects, takes over the terminal, drives until asked to quit.
pub fn run(options: &Options) -> anyhow::Result<()> {
    options.settings.validate().map_err(anyhow::Error::msg)?;
    install_signal_handlers();
    let mut robot = Robot::connect(&options.name)?;
    let source = robot
        .source(&options.source)
        .with_context(|| format!("publishing as source '{}'", options.source))?;
    let mut outlet = Outlet {
        source,
        moving: false,
    };
    let mut screen = Screen::enter().context("setting up the terminal")?;
    let result = drive(&mut robot, &mut outlet, &mut screen, options);
    let stopped = outlet.stop_if_moving();
    drop(screen);
    result.and(stopped.map_err(anyhow::Error::from))
}

/// Our source, remembering whether the robot may be moving on our command.
struct Outlet {
    source: Source,
    moving: bool,
}

impl Outlet {
    fn drive(&mut self, command: keys::Command) -> Result<(), chassis_client::ClientError> {
        self.source.send(VelocityRequest::twist(
            command.linear_mps,
            command.angular_radps,
        ))?;
        self.moving = true;
        Ok(())
    }

    fn stop(&mut self) -> Result<(), chassis_client::ClientError> {
        self.source.stop()?;
        self.moving = false;
        Ok(())
    }

    fn stop_if_moving(&mut self) -> Result<(), chassis_client::ClientError> {
        if self.moving { self.stop() } else { Ok(()) }
    }
}

impl Drop for Outlet {
    fn drop(&mut self) {
        let _ = self.stop_if_moving();
    }
}

/// Whether the keyboard enhancement flags were pushed (the panic hook pops them).
static ENHANCED: AtomicBool = AtomicBool::new(false);
static ACTIVE: AtomicBool = AtomicBool::new(false);

fn restore_terminal() {
    if !ACTIVE.swap(false, Ordering::SeqCst) {
        return;
    }
    let mut out = stdout();
    if ENHANCED.swap(false, Ordering::SeqCst) {
        let _ = execute!(out, PopKeyboardEnhancementFlags);
    }
    let _ = execute!(out, DisableFocusChange, LeaveAlternateScreen, cursor::Show);
    let _ = disable_raw_mode();
    let _ = out.flush();
}

/// The terminal in raw mode on the alternate screen; restored when dropped.
struct Screen {
    terminal: Terminal<CrosstermBackend<Stdout>>,
    releases: Releases,
}

impl Screen {
    fn enter() -> std::io::Result<Self> {
        static HOOK: Once = Once::new();
        HOOK.call_once(|| {
            let previous = std::panic::take_hook();
            std::panic::set_hook(Box::new(move |info| {
                restore_terminal();
                previous(info);
            }));
        });
        enable_raw_mode()?;
        ACTIVE.store(true, Ordering::SeqCst);
        // From here on a failure restores the terminal as this guard would.
        let screen = (|| {
            let enhanced = supports_keyboard_enhancement().unwrap_or(false);
            let mut out = stdout();
            execute!(out, EnterAlternateScreen, EnableFocusChange, cursor::Hide)?;
            if enhanced {
                execute!(
                    out,
                    PushKeyboardEnhancementFlags(
                        KeyboardEnhancementFlags::DISAMBIGUATE_ESCAPE_CODES
                            | KeyboardEnhancementFlags::REPORT_EVENT_TYPES
                    )
                )?;
                ENHANCED.store(true, Ordering::SeqCst);
            }
            let terminal = Terminal::new(CrosstermBackend::new(stdout()))?;
            Ok(Self {
                terminal,
                releases: if enhanced {
                    Releases::Reported
                } else {
                    Releases::Inferred
                },
            })
        })();
        if screen.is_err() {
            restore_terminal();
        }
        screen
    }
}

impl Drop for Screen {
    fn drop(&mut self) {
        restore_terminal();
    }
}

/// What the loop keeps between ticks.
struct Seen {
    description: Option<RobotDescription>,
    state: Option<ChassisState>,
    mux: Option<MuxStatus>,
    message: Option<String>,
    last_served_check: u64,
}

fn drive(
    robot: &mut Robot,
    outlet: &mut Outlet,
    screen: &mut Screen,
    options: &Options,
) -> anyhow::Result<()> {
    let mut teleop = Teleop::new(options.settings);
    let description = match robot.description(DESCRIPTION_WAIT) {
        Ok(d) => Some(d),
        // An older chassisd: the steps are the command line's alone.
        Err(ClientError::NoDescription { .. }) => None,
        Err(e) => return Err(e.into()),
    };
    if let Some(d) = &description {
        teleop.set_limits(keys::Limits::of(d));
    }
    let mut seen = Seen {
        description,
        state: None,
        mux: None,
        message: None,
        last_served_check: now_ns(),
    };
    let mut next_tick = now_ns();
    loop {
        if termination_requested() {
            return Ok(());
        }
        let now = now_ns();
        if now >= next_tick {
            if refresh(robot, &mut seen, now)?
                && let Some(d) = &seen.description
            {
                teleop.set_limits(keys::Limits::of(d));
            }
            draw(screen, &teleop, &seen, options, now).context("drawing the screen")?;
            // A late tick skips the missed ones instead of bunching up.
            next_tick = next_tick.saturating_add(TICK_NS);
            if next_tick <= now {
                next_tick = now.saturating_add(TICK_NS);
            }
        }
        let wake = teleop.deadline().map_or(next_tick, |d| d.min(next_tick));
        let timeout = Duration::from_nanos(wake.saturating_sub(now_ns()));
        if event::poll(timeout).context("reading the terminal")? {
            let event = event::read().context("reading the terminal")?;
            if matches!(event, Event::Resize(..)) {
                // `draw` resizes the buffers; redraw now.
                next_tick = now_ns();
            }
            if let Some(input) = keys::input(&event)
                && let Some(action) = teleop.handle(now_ns(), input)
            {
                if act(action, robot, outlet, &mut seen)? {
                    return Ok(());
                }
                // Show the change at once.
                next_tick = now_ns();
            }
        }
        if let Some(action) = teleop.poll(now_ns())
            && act(action, robot, outlet, &mut seen)?
        {
            return Ok(());
        }
    }
}

/// Carries out one action; true to quit.
fn act(
    action: Action,
    robot: &mut Robot,
    outlet: &mut Outlet,
    seen: &mut Seen,
) -> anyhow::Result<bool> {
    match action {
        Action::Drive(command) => outlet.drive(command)?,
        Action::Stop => outlet.stop()?,
        Action::Quit => {
            outlet.stop_if_moving()?;
            return Ok(true);
        }
        Action::Estop => {
            let mux = robot.latest_mux()?;
            match mux.as_ref().and_then(|m| m.lock_index("estop")) {
                Some(index) => {
                    outlet.source.stop_and_lock(1 << index)?;
                    outlet.moving = false;
                    seen.message = None;
                }
                None => {
                    outlet.stop()?;
                    seen.message = Some(if mux.is_none() {
                        "no mux status yet: stopped, but could not engage the e-stop lock".into()
                    } else {
                        "chassisd has no `estop` lock configured: stopped only".into()
                    });
                }
            }
            seen.mux = mux.or(seen.mux);
        }
    }
    Ok(false)
}

/// Reads what is new; true when a newer description came.
fn refresh(robot: &mut Robot, seen: &mut Seen, now: u64) -> anyhow::Result<bool> {
    let mut described = false;
    if let Some(d) = robot.latest_description()?
        && seen
            .description
            .is_none_or(|old| (old.seq, old.stamp_ns) != (d.seq, d.stamp_ns))
    {
        seen.description = Some(d);
        described = true;
    }
    if let Some(state) = robot.latest_state()? {
        seen.state = Some(state);
    }
    if let Some(mux) = robot.latest_mux()? {
        seen.mux = Some(mux);
    }
    let stale = seen
        .state
        .is_none_or(|s| now.saturating_sub(s.stamp_ns) > SERVED_CHECK_NS);
    if stale && now.saturating_sub(seen.last_served_check) >= SERVED_CHECK_NS {
        seen.last_served_check = now;
        if !robot.is_served() {
            seen.message = Some(format!(
                "chassis/{} is not served — is chassisd running?",
                robot.name()
            ));
        } else if seen
            .message
            .as_deref()
            .is_some_and(|m| m.contains("not served"))
        {
            seen.message = None;
        }
    }
    Ok(described)
}

fn draw(
    screen: &mut Screen,
    teleop: &Teleop,
    seen: &Seen,
    options: &Options,
    now: u64,
) -> std::io::Result<()> {
    let settings = teleop.settings();
    let (linear_mps, angular_radps) = teleop.speeds();
    let view = View {
        robot: &options.name,
        source: &options.source,
        now_ns: now,
        description: seen.description.as_ref(),
        state: seen.state.as_ref(),
        mux: seen.mux.as_ref(),
        keys: KeysView {
            held: teleop.held(),
            level: teleop.level(),
            max_level: teleop.max_level(),
            limits: teleop.limits(),
            linear_mps,
            angular_radps,
            command: teleop.command(),
            driving: teleop.is_driving(),
            releases: screen.releases,
            first_hold_ms: settings.first_hold_ns / 1_000_000,
            repeat_hold_ms: settings.repeat_hold_ns / 1_000_000,
        },
        message: seen.message.as_deref(),
    };
    screen
        .terminal
        .draw(|frame| view::render(frame, &view))
        .map(|_| ())
}
