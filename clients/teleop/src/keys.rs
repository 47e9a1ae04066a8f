//! The keyboard as a pure state machine: terminal events and the time go in, the keys held and
//! the command to publish come out. No terminal and no clock: tests move time by hand.
//!
//! # Knowing when a key is released
//!
//! Most terminals report key presses only. Where the terminal speaks the kitty keyboard protocol
//! (kitty, WezTerm, foot, Ghostty, recent Alacritty; the loop asks with
//! `PushKeyboardEnhancementFlags(REPORT_EVENT_TYPES)`), real [`Edge::Release`] events end a hold
//! at once. Everywhere else — tmux, screen, most terminals behind SSH — a release is inferred
//! from the keyboard's auto-repeat: a key held down is pressed once, then, after the repeat delay
//! (250-660 ms; X11's default is 660 ms, GNOME's and Windows' 500 ms), again at 25-33 Hz (X11,
//! GNOME, Windows) or about 11 Hz (macOS's default). So:
//!
//! * a first press holds the keys for [`Settings::first_hold_ns`] (700 ms: X11's 660 ms delay
//!   and a little network jitter), long enough for auto-repeat to begin;
//! * every repeat holds them for [`Settings::repeat_hold_ns`] (200 ms: at 30 Hz that survives
//!   five lost or late repeats, at macOS's 11 Hz one, and SSH jitter of ~100 ms without the
//!   robot stuttering) — so the robot stops 100-200 ms after the key comes up;
//! * a press of a key already held *is* a repeat (that is all a legacy terminal sends);
//! * the deadline is shared by every held motion key, because a keyboard repeats only the key
//!   pressed last: holding `w` and then `d`, only `d` repeats, and it keeps both alive. When
//!   `d` comes up the deadline lapses and both end — the robot stops instead of guessing that
//!   `w` is still down (press `w` again). Release events, where there are any, end one key
//!   exactly; the hold windows apply in both modes, so a stalled SSH link or a lost release
//!   event still stops the robot within the window.
//!
//! The cost of inferring: a single tap drives for up to 700 ms. Both windows are options.
//!
//! While a motion key is held the command is published every [`Settings::period_ns`] (20 Hz),
//! and at once whenever it changes.
//!
//! The speed steps stop at the robot's effective limits ([`Limits`], from the description
//! chassisd publishes: the robot's own after every `[profile]` override, tightened by
//! `[mux.limits]`): forward and reverse each, and the yaw rate where the robot has a limit, so
//! no step asks for more than the robot will do. When the last key ends, one explicit stop goes out and then
//! nothing, so the mux's timeout hands the robot back to lower-priority sources (the planner).

use crossterm::event::{Event, KeyCode, KeyEvent, KeyEventKind, KeyModifiers};
use thiserror::Error;

/// A motion key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    Forward,
    Reverse,
    Left,
    Right,
}

impl Motion {
    const fn bit(self) -> u8 {
        1 << self as u8
    }
}

/// A key the teleop knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Key {
    /// Arrows and WASD.
    Motion(Motion),
    /// `+` (or `=`, the same key unshifted on US layouts): one speed step up.
    Faster,
    /// `-`: one speed step down.
    Slower,
    /// Space: stop now.
    Stop,
    /// `e`: engage the e-stop lock.
    Estop,
    /// `q`, Esc, Ctrl-C.
    Quit,
}

/// What happened to a key. Legacy terminals only ever send [`Edge::Press`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edge {
    Press,
    Repeat,
    Release,
}

/// A terminal event the teleop cares about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    Key(Key, Edge),
    FocusLost,
    FocusGained,
}

/// Maps a crossterm event to an [`Input`] (`None`: not ours).
pub fn input(event: &Event) -> Option<Input> {
    match event {
        Event::FocusLost => Some(Input::FocusLost),
        Event::FocusGained => Some(Input::FocusGained),
        Event::Key(key) => key_input(key),
        _ => None,
    }
}

fn key_input(event: &KeyEvent) -> Option<Input> {
    let edge = match event.kind {
        KeyEventKind::Press => Edge::Press,
        KeyEventKind::Repeat => Edge::Repeat,
        KeyEventKind::Release => Edge::Release,
    };
    let control = event.modifiers.contains(KeyModifiers::CONTROL);
    if control && matches!(event.code, KeyCode::Char('c' | 'C')) {
        return Some(Input::Key(Key::Quit, edge));
    }
    if control || event.modifiers.contains(KeyModifiers::ALT) {
        return None;
    }
    let key = match event.code {
        KeyCode::Up | KeyCode::Char('w' | 'W') => Key::Motion(Motion::Forward),
        KeyCode::Down | KeyCode::Char('s' | 'S') => Key::Motion(Motion::Reverse),
        KeyCode::Left | KeyCode::Char('a' | 'A') => Key::Motion(Motion::Left),
        KeyCode::Right | KeyCode::Char('d' | 'D') => Key::Motion(Motion::Right),
        KeyCode::Char('+' | '=') => Key::Faster,
        KeyCode::Char('-' | '_') => Key::Slower,
        KeyCode::Char(' ') => Key::Stop,
        KeyCode::Char('e' | 'E') => Key::Estop,
        KeyCode::Char('q' | 'Q') | KeyCode::Esc => Key::Quit,
        _ => return None,
    };
    Some(Input::Key(key, edge))
}

/// A motion command: forward speed and yaw rate (left turn positive).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Command {
    pub linear_mps: f32,
    pub angular_radps: f32,
}

/// What the loop must do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Action {
    /// Publish this command.
    Drive(Command),
    /// Publish one explicit stop.
    Stop,
    /// Stop and engage the e-stop lock.
    Estop,
    /// Stop if moving, then quit.
    Quit,
}

/// Speeds and timings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Forward speed per speed step, m/s.
    pub linear_step_mps: f32,
    /// Yaw rate per speed step, rad/s.
    pub angular_step_radps: f32,
    pub max_linear_mps: f32,
    pub max_angular_radps: f32,
    /// How long a first press holds the keys, ns.
    pub first_hold_ns: u64,
    /// How long a repeat holds them, ns.
    pub repeat_hold_ns: u64,
    /// Publishing period while a key is held, ns.
    pub period_ns: u64,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            linear_step_mps: 0.1,
            angular_step_radps: 0.2,
            max_linear_mps: 1.0,
            max_angular_radps: 1.0,
            first_hold_ns: 700_000_000,
            repeat_hold_ns: 200_000_000,
            period_ns: 50_000_000,
        }
    }
}

/// Why the teleop settings are not usable.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SettingsError {
    /// A speed or step that is zero, negative or not a number.
    #[error("{option} must be a positive number, not {value}")]
    NotPositive { option: &'static str, value: f32 },
    #[error("--linear-step is above --max-linear")]
    LinearStepAboveMax,
    #[error("--angular-step is above --max-angular")]
    AngularStepAboveMax,
    #[error("the repeat hold must be above 0 and at most the first-press hold")]
    RepeatHold,
    #[error("the publishing period must be above 0")]
    ZeroPeriod,
}

impl Settings {
    /// Checks the speeds are positive and finite and the steps fit under the maxima.
    pub fn validate(&self) -> Result<(), SettingsError> {
        let positive = |value: f32, option: &'static str| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(SettingsError::NotPositive { option, value })
            }
        };
        positive(self.linear_step_mps, "--linear-step")?;
        positive(self.angular_step_radps, "--angular-step")?;
        positive(self.max_linear_mps, "--max-linear")?;
        positive(self.max_angular_radps, "--max-angular")?;
        if self.linear_step_mps > self.max_linear_mps {
            return Err(SettingsError::LinearStepAboveMax);
        }
        if self.angular_step_radps > self.max_angular_radps {
            return Err(SettingsError::AngularStepAboveMax);
        }
        if self.repeat_hold_ns == 0 || self.first_hold_ns < self.repeat_hold_ns {
            return Err(SettingsError::RepeatHold);
        }
        if self.period_ns == 0 {
            return Err(SettingsError::ZeroPeriod);
        }
        Ok(())
    }

    /// Speed steps from the slowest to where both speeds reached their maximum.
    pub fn max_level(&self) -> u32 {
        let steps = |max: f32, step: f32| (max / step - 1e-4).ceil().max(1.0);
        // At most a few hundred steps for any sane setting; saturates otherwise.
        steps(self.max_linear_mps, self.linear_step_mps)
            .max(steps(self.max_angular_radps, self.angular_step_radps))
            .min(1000.0) as u32
    }
}

/// The robot's effective limits, as its description gives them (infinite: none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub forward_mps: f32,
    pub reverse_mps: f32,
    pub angular_radps: f32,
}

impl Limits {
    /// No limit known (no description yet).
    pub const NONE: Limits = Limits {
        forward_mps: f32::INFINITY,
        reverse_mps: f32::INFINITY,
        angular_radps: f32::INFINITY,
    };

    /// The effective limits of a description; an unset (NaN) or non-positive one is none.
    pub fn of(d: &chassis_client::RobotDescription) -> Self {
        let e = d.effective_limits();
        let limit = |v: f64| {
            if v.is_finite() && v > 0.0 {
                // Never above the limit once widened again (0.3 is 0.30000001 as an f32), or
                // the driver clamps a step at the limit.
                let narrow = v as f32;
                if f64::from(narrow) > v {
                    narrow.next_down()
                } else {
                    narrow
                }
            } else {
                f32::INFINITY
            }
        };
        let forward = limit(e.forward_mps);
        Limits {
            forward_mps: forward,
            reverse_mps: if e.reverse_mps.is_nan() {
                forward
            } else {
                limit(e.reverse_mps)
            },
            angular_radps: limit(e.angular_radps),
        }
    }
}

/// The set of motion keys held.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Held(u8);

impl Held {
    pub fn contains(self, motion: Motion) -> bool {
        self.0 & motion.bit() != 0
    }
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
    fn insert(&mut self, motion: Motion) {
        self.0 |= motion.bit();
    }
    fn remove(&mut self, motion: Motion) {
        self.0 &= !motion.bit();
    }
}

/// The teleop's keyboard state.
#[derive(Debug, Clone)]
pub struct Teleop {
    settings: Settings,
    held: Held,
    /// When the held keys count as released unless a repeat (or a new press) comes first.
    hold_until_ns: u64,
    /// Speed step, 1 ..= max level.
    level: u32,
    /// The robot's effective limits.
    limits: Limits,
    /// When the command is due again while driving.
    next_send_ns: u64,
}

impl Teleop {
    pub fn new(settings: Settings) -> Self {
        Self {
            settings,
            held: Held::default(),
            hold_until_ns: 0,
            level: 1,
            limits: Limits::NONE,
            next_send_ns: 0,
        }
    }

    /// The robot's effective limits (a description, or a newer one): the steps stop there.
    pub fn set_limits(&mut self, limits: Limits) {
        self.limits = limits;
        self.level = self.level.min(self.max_level());
    }

    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// Largest forward or reverse speed a step asks for.
    fn max_linear(&self) -> f32 {
        let robot = self.limits.forward_mps.max(self.limits.reverse_mps);
        self.settings.max_linear_mps.min(robot)
    }

    fn max_angular(&self) -> f32 {
        self.settings
            .max_angular_radps
            .min(self.limits.angular_radps)
    }

    /// Speed steps from the slowest to where both speeds reached their maximum, within the
    /// robot's limits.
    pub fn max_level(&self) -> u32 {
        Settings {
            max_linear_mps: self.max_linear().max(self.settings.linear_step_mps),
            max_angular_radps: self.max_angular().max(self.settings.angular_step_radps),
            ..self.settings
        }
        .max_level()
    }

    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    pub fn held(&self) -> Held {
        self.held
    }

    /// True while a motion key is held (the command is being published).
    pub fn is_driving(&self) -> bool {
        !self.held.is_empty()
    }

    pub fn level(&self) -> u32 {
        self.level
    }

    /// Forward speed and yaw rate of the current speed step.
    pub fn speeds(&self) -> (f32, f32) {
        let level = self.level as f32;
        (
            (level * self.settings.linear_step_mps).min(self.max_linear()),
            (level * self.settings.angular_step_radps).min(self.max_angular()),
        )
    }

    /// The command the held keys ask for (zero when none is held; opposite keys cancel),
    /// forward and reverse each within the robot's limit.
    pub fn command(&self) -> Command {
        let (v, w) = self.speeds();
        let axis = |plus: Motion, minus: Motion| {
            f32::from(u8::from(self.held.contains(plus)))
                - f32::from(u8::from(self.held.contains(minus)))
        };
        let linear = axis(Motion::Forward, Motion::Reverse);
        let speed = if linear > 0.0 {
            v.min(self.limits.forward_mps)
        } else {
            v.min(self.limits.reverse_mps)
        };
        Command {
            linear_mps: linear * speed,
            angular_radps: axis(Motion::Left, Motion::Right) * w,
        }
    }

    /// The next time [`Teleop::poll`] has something to do.
    pub fn deadline(&self) -> Option<u64> {
        self.is_driving()
            .then(|| self.hold_until_ns.min(self.next_send_ns))
    }

    /// Handles one input at `now_ns`.
    pub fn handle(&mut self, now_ns: u64, input: Input) -> Option<Action> {
        match input {
            Input::FocusLost => self.release_all(),
            Input::FocusGained => None,
            Input::Key(Key::Motion(motion), Edge::Release) => {
                if !self.held.contains(motion) {
                    return None;
                }
                self.held.remove(motion);
                if self.held.is_empty() {
                    Some(Action::Stop)
                } else {
                    Some(self.drive_now(now_ns))
                }
            }
            Input::Key(Key::Motion(motion), edge) => {
                let repeat = edge == Edge::Repeat || self.held.contains(motion);
                let was_driving = self.is_driving();
                let before = self.command();
                self.held.insert(motion);
                self.hold_until_ns = now_ns.saturating_add(if repeat {
                    self.settings.repeat_hold_ns
                } else {
                    self.settings.first_hold_ns
                });
                (!was_driving || self.command() != before).then(|| self.drive_now(now_ns))
            }
            // Releases of the other keys mean nothing.
            Input::Key(_, Edge::Release) => None,
            Input::Key(Key::Faster, _) => self.step(now_ns, true),
            Input::Key(Key::Slower, _) => self.step(now_ns, false),
            Input::Key(Key::Stop, _) => {
                self.held = Held::default();
                Some(Action::Stop)
            }
            Input::Key(Key::Estop, _) => {
                self.held = Held::default();
                Some(Action::Estop)
            }
            Input::Key(Key::Quit, _) => {
                self.held = Held::default();
                Some(Action::Quit)
            }
        }
    }

    /// Ends holds whose window lapsed and re-sends the command when due.
    pub fn poll(&mut self, now_ns: u64) -> Option<Action> {
        if !self.is_driving() {
            return None;
        }
        if now_ns >= self.hold_until_ns {
            self.held = Held::default();
            return Some(Action::Stop);
        }
        if now_ns >= self.next_send_ns {
            self.next_send_ns = self.next_send_ns.saturating_add(self.settings.period_ns);
            if self.next_send_ns <= now_ns {
                self.next_send_ns = now_ns.saturating_add(self.settings.period_ns);
            }
            return Some(Action::Drive(self.command()));
        }
        None
    }

    fn drive_now(&mut self, now_ns: u64) -> Action {
        self.next_send_ns = now_ns.saturating_add(self.settings.period_ns);
        Action::Drive(self.command())
    }

    fn step(&mut self, now_ns: u64, up: bool) -> Option<Action> {
        let before = self.command();
        self.level = if up {
            (self.level + 1).min(self.max_level())
        } else {
            self.level.saturating_sub(1).max(1)
        };
        (self.is_driving() && self.command() != before).then(|| self.drive_now(now_ns))
    }

    fn release_all(&mut self) -> Option<Action> {
        let was_driving = self.is_driving();
        self.held = Held::default();
        was_driving.then_some(Action::Stop)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crossterm::event::KeyEventState;

    const MS: u64 = 1_000_000;

    fn press(motion: Motion) -> Input {
        Input::Key(Key::Motion(motion), Edge::Press)
    }

    fn repeat(motion: Motion) -> Input {
        Input::Key(Key::Motion(motion), Edge::Repeat)
    }

    fn release(motion: Motion) -> Input {
        Input::Key(Key::Motion(motion), Edge::Release)
    }

    fn drive(linear_mps: f32, angular_radps: f32) -> Option<Action> {
        Some(Action::Drive(Command {
            linear_mps,
            angular_radps,
        }))
    }

    /// Feeds `inputs` at their times and polls every `step` ms up to `until` ms; returns every
    /// action with its time in ms.
    fn run(
        teleop: &mut Teleop,
        inputs: &[(u64, Input)],
        until: u64,
        step: u64,
    ) -> Vec<(u64, Action)> {
        let mut out = Vec::new();
        let mut inputs = inputs.iter().peekable();
        let mut t = 0;
        while t <= until {
            while let Some((at, input)) = inputs.peek() {
                if *at > t {
                    break;
                }
                if let Some(a) = teleop.handle(at * MS, *input) {
                    out.push((*at, a));
                }
                inputs.next();
            }
            if let Some(a) = teleop.poll(t * MS) {
                out.push((t, a));
            }
            t += step;
        }
        out
    }

    #[test]
    fn a_first_press_drives_at_once_and_publishes_at_20_hz() {
        let mut t = Teleop::new(Settings::default());
        assert_eq!(t.handle(0, press(Motion::Forward)), drive(0.1, 0.0));
        assert_eq!(t.deadline(), Some(50 * MS));
        assert_eq!(t.poll(49 * MS), None);
        assert_eq!(t.poll(50 * MS), drive(0.1, 0.0));
        assert_eq!(t.poll(100 * MS), drive(0.1, 0.0));
    }

    #[test]
    fn a_tap_without_repeats_stops_after_the_first_press_window() {
        let mut t = Teleop::new(Settings::default());
        let actions = run(&mut t, &[(0, press(Motion::Forward))], 2000, 10);
        let stops: Vec<u64> = actions
            .iter()
            .filter(|(_, a)| *a == Action::Stop)
            .map(|(at, _)| *at)
            .collect();
        assert_eq!(stops, vec![700], "one stop, when the 700 ms window lapses");
        let drives = actions
            .iter()
            .filter(|(_, a)| matches!(a, Action::Drive(_)))
            .count();
        // At 0 ms, then every 50 ms up to 650 ms.
        assert_eq!(drives, 14);
        assert!(!t.is_driving());
        assert_eq!(t.deadline(), None, "nothing more is sent");
    }

    #[test]
    fn auto_repeat_keeps_a_key_held_and_its_end_stops_within_the_repeat_window() {
        let mut t = Teleop::new(Settings::default());
        // X11 defaults: 660 ms delay, then 25 Hz, until 2000 ms.
        let mut inputs = vec![(0, press(Motion::Forward))];
        let mut at = 660;
        while at <= 2000 {
            inputs.push((at, press(Motion::Forward)));
            at += 40;
        }
        let last = inputs.last().map_or(0, |(at, _)| *at);
        let actions = run(&mut t, &inputs, 3000, 5);
        let first_stop = actions
            .iter()
            .find(|(_, a)| *a == Action::Stop)
            .map(|(at, _)| *at);
        assert_eq!(first_stop, Some(last + 200));
        assert!(
            actions
                .iter()
                .filter(|(at, _)| *at < last + 200)
                .all(|(_, a)| *a
                    == Action::Drive(Command {
                        linear_mps: 0.1,
                        angular_radps: 0.0
                    })),
            "no gap while the key repeats"
        );
    }

    #[test]
    fn a_release_event_stops_at_once() {
        let mut t = Teleop::new(Settings::default());
        t.handle(0, press(Motion::Forward));
        t.handle(500 * MS, repeat(Motion::Forward));
        assert_eq!(
            t.handle(510 * MS, release(Motion::Forward)),
            Some(Action::Stop)
        );
        assert_eq!(t.poll(2000 * MS), None, "one stop, then nothing");
    }

    #[test]
    fn the_window_still_applies_when_release_events_are_lost() {
        let mut t = Teleop::new(Settings::default());
        t.handle(0, press(Motion::Forward));
        t.handle(100 * MS, repeat(Motion::Forward));
        assert_eq!(t.poll(299 * MS), drive(0.1, 0.0));
        assert_eq!(t.poll(300 * MS), Some(Action::Stop));
    }

    #[test]
    fn combinations_add_and_opposite_keys_cancel() {
        let mut t = Teleop::new(Settings::default());
        t.handle(0, press(Motion::Forward));
        assert_eq!(t.handle(10 * MS, press(Motion::Left)), drive(0.1, 0.2));
        assert_eq!(t.handle(20 * MS, press(Motion::Right)), drive(0.1, 0.0));
        assert_eq!(t.handle(30 * MS, press(Motion::Reverse)), drive(0.0, 0.0));
        assert!(
            t.is_driving(),
            "holding opposite keys holds the robot still"
        );
        assert_eq!(
            t.handle(40 * MS, release(Motion::Forward)),
            drive(-0.1, 0.0)
        );
    }

    #[test]
    fn the_last_pressed_key_repeating_keeps_the_whole_combination_held() {
        let mut t = Teleop::new(Settings::default());
        t.handle(0, press(Motion::Forward));
        // `w` repeats, then `d` is pressed: only `d` repeats from then on.
        for at in (500..=1000).step_by(40) {
            t.handle(at * MS, press(Motion::Forward));
        }
        assert_eq!(t.handle(1010 * MS, press(Motion::Right)), drive(0.1, -0.2));
        // The first press of `d` holds both for the repeat delay.
        assert_eq!(t.poll(1600 * MS), drive(0.1, -0.2));
        for at in (1600..=2000).step_by(40) {
            t.handle(at * MS, press(Motion::Right));
        }
        assert_eq!(t.poll(2150 * MS), drive(0.1, -0.2));
        assert_eq!(t.poll(2200 * MS), Some(Action::Stop), "both end with `d`");
    }

    #[test]
    fn a_held_key_that_comes_back_after_a_lapse_drives_again() {
        let mut t = Teleop::new(Settings::default());
        t.handle(0, press(Motion::Forward));
        assert_eq!(t.poll(700 * MS), Some(Action::Stop));
        assert_eq!(t.handle(900 * MS, press(Motion::Forward)), drive(0.1, 0.0));
    }

    #[test]
    fn plus_and_minus_change_the_speed_step_within_the_limits() {
        let settings = Settings {
            max_linear_mps: 0.3,
            max_angular_radps: 0.4,
            ..Settings::default()
        };
        assert_eq!(settings.max_level(), 3);
        let mut t = Teleop::new(settings);
        assert_eq!(t.handle(0, Input::Key(Key::Faster, Edge::Press)), None);
        assert_eq!(t.level(), 2);
        t.handle(0, Input::Key(Key::Faster, Edge::Press));
        t.handle(0, Input::Key(Key::Faster, Edge::Press));
        assert_eq!(t.level(), 3);
        let (v, w) = t.speeds();
        assert!((v - 0.3).abs() < 1e-6 && (w - 0.4).abs() < 1e-6, "{v} {w}");
        // While driving a step is sent at once.
        t.handle(MS, press(Motion::Reverse));
        let sent = t.handle(2 * MS, Input::Key(Key::Slower, Edge::Press));
        assert_eq!(sent, drive(-0.2, 0.0));
        for _ in 0..5 {
            t.handle(3 * MS, Input::Key(Key::Slower, Edge::Press));
        }
        assert_eq!(t.level(), 1);
    }

    #[test]
    fn the_steps_stop_at_the_robots_effective_limits() {
        // 1.0 m/s and 1.0 rad/s in steps of 0.1 and 0.2 asked; the robot does 0.45 m/s forward,
        // 0.25 m/s reverse and 0.5 rad/s.
        let mut t = Teleop::new(Settings::default());
        assert_eq!(t.max_level(), 10);
        t.set_limits(Limits {
            forward_mps: 0.45,
            reverse_mps: 0.25,
            angular_radps: 0.5,
        });
        assert_eq!(t.max_level(), 5, "0.45 m/s in steps of 0.1");
        for _ in 0..20 {
            t.handle(0, Input::Key(Key::Faster, Edge::Press));
        }
        assert_eq!(t.level(), 5);
        let (v, w) = t.speeds();
        assert!((v - 0.45).abs() < 1e-6 && (w - 0.5).abs() < 1e-6, "{v} {w}");
        assert_eq!(t.handle(MS, press(Motion::Forward)), drive(0.45, 0.0));
        t.handle(2 * MS, Input::FocusLost);
        assert_eq!(t.handle(3 * MS, press(Motion::Reverse)), drive(-0.25, 0.0));
        t.handle(4 * MS, Input::FocusLost);
        assert_eq!(t.handle(5 * MS, press(Motion::Left)), drive(0.0, 0.5));
        // Tighter limits later (a newer description) bring the step down with them.
        t.set_limits(Limits {
            forward_mps: 0.2,
            reverse_mps: 0.2,
            angular_radps: f32::INFINITY,
        });
        assert_eq!(t.level(), 5, "the yaw rate still has five steps");
        assert!((t.speeds().0 - 0.2).abs() < 1e-6);
        t.set_limits(Limits::NONE);
        assert_eq!(t.max_level(), 10);
    }

    #[test]
    fn limits_come_from_the_description_and_nan_is_no_limit() {
        let mut d = chassis_client::RobotDescription::default();
        d.robot_limits.forward_mps = 1.5;
        d.robot_limits.angular_radps = 0.8;
        d.configured_limits.forward_mps = 0.6;
        let l = Limits::of(&d);
        assert!((l.forward_mps - 0.6).abs() < 1e-6, "{}", l.forward_mps);
        assert_eq!(l.reverse_mps, l.forward_mps, "reverse unset: as forward");
        assert!((l.angular_radps - 0.8).abs() < 1e-6);
        d.robot_limits.angular_radps = f64::NAN;
        d.robot_limits.reverse_mps = 1.0;
        let l = Limits::of(&d);
        assert_eq!(l.angular_radps, f32::INFINITY);
        assert_eq!(l.reverse_mps, 1.0);
        // 0.3 m/s is a little more as an f32: the step stays below the limit.
        d.configured_limits.forward_mps = 0.3;
        let l = Limits::of(&d);
        assert!(f64::from(l.forward_mps) <= 0.3, "{}", l.forward_mps);
        assert!(f64::from(l.forward_mps) > 0.3 - 1e-6);
    }

    #[test]
    fn space_stops_even_when_nothing_is_held_and_clears_the_keys() {
        let mut t = Teleop::new(Settings::default());
        assert_eq!(
            t.handle(0, Input::Key(Key::Stop, Edge::Press)),
            Some(Action::Stop)
        );
        t.handle(MS, press(Motion::Forward));
        assert_eq!(
            t.handle(2 * MS, Input::Key(Key::Stop, Edge::Press)),
            Some(Action::Stop)
        );
        assert!(!t.is_driving());
        assert_eq!(t.poll(100 * MS), None);
    }

    #[test]
    fn focus_loss_stops_a_driving_robot_and_is_silent_otherwise() {
        let mut t = Teleop::new(Settings::default());
        assert_eq!(t.handle(0, Input::FocusLost), None);
        t.handle(MS, press(Motion::Left));
        assert_eq!(t.handle(2 * MS, Input::FocusLost), Some(Action::Stop));
        assert!(!t.is_driving());
        assert_eq!(t.handle(3 * MS, Input::FocusGained), None);
    }

    #[test]
    fn estop_and_quit_clear_the_keys() {
        let mut t = Teleop::new(Settings::default());
        t.handle(0, press(Motion::Forward));
        assert_eq!(
            t.handle(MS, Input::Key(Key::Estop, Edge::Press)),
            Some(Action::Estop)
        );
        assert!(!t.is_driving());
        t.handle(2 * MS, press(Motion::Forward));
        assert_eq!(
            t.handle(3 * MS, Input::Key(Key::Quit, Edge::Press)),
            Some(Action::Quit)
        );
        assert!(!t.is_driving());
        assert_eq!(
            t.handle(4 * MS, Input::Key(Key::Quit, Edge::Release)),
            None,
            "releases of command keys do nothing"
        );
    }

    fn key(code: KeyCode, modifiers: KeyModifiers, kind: KeyEventKind) -> Event {
        Event::Key(KeyEvent {
            code,
            modifiers,
            kind,
            state: KeyEventState::NONE,
        })
    }

    #[test]
    fn arrows_wasd_and_command_keys_map_to_inputs() {
        let none = KeyModifiers::NONE;
        let p = KeyEventKind::Press;
        let cases = [
            (KeyCode::Up, Key::Motion(Motion::Forward)),
            (KeyCode::Char('w'), Key::Motion(Motion::Forward)),
            (KeyCode::Char('W'), Key::Motion(Motion::Forward)),
            (KeyCode::Down, Key::Motion(Motion::Reverse)),
            (KeyCode::Char('s'), Key::Motion(Motion::Reverse)),
            (KeyCode::Left, Key::Motion(Motion::Left)),
            (KeyCode::Char('a'), Key::Motion(Motion::Left)),
            (KeyCode::Right, Key::Motion(Motion::Right)),
            (KeyCode::Char('d'), Key::Motion(Motion::Right)),
            (KeyCode::Char('+'), Key::Faster),
            (KeyCode::Char('='), Key::Faster),
            (KeyCode::Char('-'), Key::Slower),
            (KeyCode::Char(' '), Key::Stop),
            (KeyCode::Char('e'), Key::Estop),
            (KeyCode::Char('q'), Key::Quit),
            (KeyCode::Esc, Key::Quit),
        ];
        for (code, expected) in cases {
            assert_eq!(
                input(&key(code, none, p)),
                Some(Input::Key(expected, Edge::Press)),
                "{code:?}"
            );
        }
        assert_eq!(
            input(&key(KeyCode::Char('c'), KeyModifiers::CONTROL, p)),
            Some(Input::Key(Key::Quit, Edge::Press))
        );
        assert_eq!(
            input(&key(KeyCode::Char('w'), KeyModifiers::CONTROL, p)),
            None
        );
        assert_eq!(
            input(&key(KeyCode::Up, none, KeyEventKind::Release)),
            Some(Input::Key(Key::Motion(Motion::Forward), Edge::Release))
        );
        assert_eq!(
            input(&key(KeyCode::Up, none, KeyEventKind::Repeat)),
            Some(Input::Key(Key::Motion(Motion::Forward), Edge::Repeat))
        );
        assert_eq!(input(&Event::FocusLost), Some(Input::FocusLost));
        assert_eq!(input(&Event::Resize(80, 24)), None);
        assert_eq!(input(&key(KeyCode::Char('x'), none, p)), None);
    }

    #[test]
    fn settings_are_validated() {
        assert!(Settings::default().validate().is_ok());
        assert_eq!(Settings::default().max_level(), 10);
        let bad = Settings {
            linear_step_mps: f32::NAN,
            ..Settings::default()
        };
        assert!(bad.validate().is_err());
        let bad = Settings {
            linear_step_mps: 2.0,
            ..Settings::default()
        };
        assert!(bad.validate().is_err());
        let bad = Settings {
            first_hold_ns: 100,
            ..Settings::default()
        };
        assert!(bad.validate().is_err());
    }
}
