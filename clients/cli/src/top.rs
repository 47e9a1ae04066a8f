//! `chassis top`: a live dashboard of the robot as chassisd describes it, its state, mux
//! decisions, bus statistics and latency.
//!
//! The loop blocks in [`Robot::wait_state`] (at most 50 ms, so keys stay responsive), then
//! drains the frame tap and the mux status into [`stats`] and redraws every `--interval-ms`.
//! State samples that arrived while the dashboard was busy are drained *before* the wait and
//! not measured, so a latency figure is always chassisd's stamp → this process woken by the
//! sample, never the dashboard's own drawing time. What each figure means is in [`stats`] and
//! on the screen. `--once` collects for `--collect` seconds and prints the panels as text.

mod stats;
mod view;

use std::time::Duration;

use anyhow::Context;
use chassis_client::{
    ChassisState, ClientError, FrameTap, MuxStatus, Robot, RobotDescription,
    install_signal_handlers, now_ns, termination_requested,
};
use clap::Args;
use crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};

use crate::described;
use stats::{BusStats, Latency};
use view::Snapshot;

/// Frames the tap may queue between two reads.
const TAP_BUFFER: usize = 2048;
/// Longest wait for a state sample, so keys and the screen stay responsive.
const MAX_WAIT: Duration = Duration::from_millis(50);
/// Longest wait at start for the robot's description (chassisd hands it to a new reader within
/// a tick of its loop).
const DESCRIPTION_WAIT: Duration = Duration::from_millis(500);

#[derive(Debug, Args)]
pub struct TopArgs {
    /// The robot's name (chassisd --name).
    #[arg(long, default_value = "titan")]
    pub name: String,
    /// Print one text snapshot after collecting for --collect seconds, instead of the live
    /// dashboard.
    #[arg(long)]
    pub once: bool,
    /// With --once: seconds to collect before printing (rates need a full second).
    #[arg(long, default_value_t = 1.5)]
    pub collect: f64,
    /// Screen refresh period, ms.
    #[arg(long, default_value_t = 250)]
    pub interval_ms: u64,
}

/// Everything gathered so far.
struct Collector {
    bus: BusStats,
    latency: Latency,
    description: Option<RobotDescription>,
    state: Option<ChassisState>,
    mux: Option<MuxStatus>,
    start_ns: u64,
}

impl Collector {
    /// Waits at most `timeout` for a state sample, then takes in everything pending.
    fn step(&mut self, robot: &mut Robot, tap: &FrameTap, timeout: Duration) -> anyhow::Result<()> {
        // Samples that waited while we were busy: kept, not measured.
        if let Some(state) = robot.latest_state()? {
            self.latency.on_state(now_ns(), &state, false);
            self.state = Some(state);
        }
        if let Some(state) = robot.wait_state(timeout)? {
            self.latency.on_state(now_ns(), &state, true);
            self.state = Some(state);
        }
        let bus = &mut self.bus;
        tap.drain(|frame| bus.on_frame(frame))?;
        if let Some(mux) = robot.latest_mux()? {
            self.latency.on_mux(&mux);
            self.mux = Some(mux);
        }
        if let Some(d) = robot.latest_description()?
            && self
                .description
                .is_none_or(|seen| (seen.seq, seen.stamp_ns) != (d.seq, d.stamp_ns))
        {
            // Protocol detection decided, or chassisd came back with another robot: its
            // frames are named anew.
            self.bus
                .set_profile(described::profile_of(Some(&d), self.state.as_ref()).as_ref());
            self.description = Some(d);
        }
        let now = now_ns();
        self.bus.expire(now);
        self.latency.resolve(now, &self.bus);
        Ok(())
    }

    fn snapshot<'a>(&'a self, name: &'a str) -> Snapshot<'a> {
        let now = now_ns();
        Snapshot {
            name,
            now_ns: now,
            running_ns: now.saturating_sub(self.start_ns),
            description: self.description.as_ref(),
            state: self.state.as_ref(),
            mux: self.mux.as_ref(),
            bus: &self.bus,
            latency: &self.latency,
        }
    }
}

pub fn run(args: &TopArgs) -> anyhow::Result<()> {
    install_signal_handlers();
    if !(args.collect.is_finite() && args.collect > 0.0 && args.collect <= 3600.0) {
        anyhow::bail!("--collect must be above 0 and at most 3600 s");
    }
    let mut robot = Robot::connect(&args.name)?;
    let tap = robot.frames(TAP_BUFFER)?;
    // The sample the subscription inherited tells the robot; it is as old as our start-up.
    let first = match robot.latest_state()? {
        Some(state) => Some(state),
        None => robot.wait_state(Duration::from_secs(1))?,
    };
    let description = match robot.description(DESCRIPTION_WAIT) {
        Ok(d) => Some(d),
        // An older chassisd: the state's robot kind names the frames.
        Err(ClientError::NoDescription { .. }) => None,
        Err(e) => return Err(e.into()),
    };
    let profile = described::profile_of(description.as_ref(), first.as_ref());
    let mut collector = Collector {
        bus: BusStats::new(profile.as_ref()),
        latency: Latency::default(),
        description,
        state: first,
        mux: None,
        start_ns: now_ns(),
    };
    if let Some(state) = &first {
        collector.latency.on_state(now_ns(), state, false);
    }
    if args.once {
        let end = collector
            .start_ns
            .saturating_add(Duration::from_secs_f64(args.collect).as_nanos() as u64);
        while now_ns() < end && !termination_requested() {
            let left = Duration::from_nanos(end.saturating_sub(now_ns()));
            collector.step(&mut robot, &tap, left.min(MAX_WAIT))?;
        }
        print!("{}", view::text(&collector.snapshot(&args.name)));
        return Ok(());
    }
    live(&mut robot, &tap, &mut collector, args)
}

/// Restores the terminal when dropped (errors included; ratatui's panic hook covers panics).
pub(crate) struct Screen(pub(crate) ratatui::DefaultTerminal);

impl Screen {
    pub(crate) fn open() -> anyhow::Result<Screen> {
        Ok(Screen(
            ratatui::try_init().context("setting up the terminal")?,
        ))
    }
}

impl Drop for Screen {
    fn drop(&mut self) {
        ratatui::restore();
    }
}

/// q, Esc or Ctrl-C.
pub(crate) fn quit_key(event: &Event) -> bool {
    let Event::Key(key) = event else {
        return false;
    };
    key.kind != KeyEventKind::Release
        && (matches!(key.code, KeyCode::Char('q' | 'Q') | KeyCode::Esc)
            || key.modifiers.contains(KeyModifiers::CONTROL)
                && matches!(key.code, KeyCode::Char('c' | 'C')))
}

fn live(
    robot: &mut Robot,
    tap: &FrameTap,
    collector: &mut Collector,
    args: &TopArgs,
) -> anyhow::Result<()> {
    let interval_ns = args.interval_ms.clamp(20, 10_000) * 1_000_000;
    let mut screen = Screen::open()?;
    let mut next_draw = now_ns();
    while !termination_requested() {
        let wait = Duration::from_nanos(next_draw.saturating_sub(now_ns())).min(MAX_WAIT);
        collector.step(robot, tap, wait)?;
        while event::poll(Duration::ZERO).context("reading the terminal")? {
            let event = event::read().context("reading the terminal")?;
            if quit_key(&event) {
                return Ok(());
            }
            if matches!(event, Event::Resize(..)) {
                next_draw = now_ns();
            }
        }
        let now = now_ns();
        if now >= next_draw {
            let snapshot = collector.snapshot(&args.name);
            screen
                .0
                .draw(|frame| view::render(frame, &snapshot))
                .context("drawing the dashboard")?;
            next_draw = next_draw.saturating_add(interval_ns);
            if next_draw <= now {
                next_draw = now.saturating_add(interval_ns);
            }
        }
    }
    Ok(())
}
