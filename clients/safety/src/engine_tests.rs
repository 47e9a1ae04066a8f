//! The rule engine on simulated time.

use super::*;
use crate::config::Origin;
use crate::config::RawConfig;
use chassis_client::ControlMode;
use chassis_protocols::RobotKind;
use chassis_protocols::description::describe;

/// Simulated time starts here (ms), so "never" (0) is long ago.
const T0_MS: u64 = 10_000;

fn ns(ms: u64) -> u64 {
    (T0_MS + ms) * 1_000_000
}

/// An engine, a robot's state that refreshes at every step, and the mux as the service shows it.
struct Rig {
    engine: Engine,
    state: ChassisState,
    mux: Option<MuxStatus>,
    /// Simulated time, ms since T0.
    now_ms: u64,
    /// The state stops refreshing (the service is silent).
    frozen: bool,
    /// The driver reports the command it puts on the wire.
    wire: bool,
}

fn mux_with_estop() -> MuxStatus {
    let mut m = MuxStatus {
        seq: 1,
        source_count: 3,
        lock_count: 1,
        ..MuxStatus::default()
    };
    m.sources[0].set_name("safety");
    m.sources[1].set_name("teleop");
    m.sources[2].set_name("planner");
    m.locks[0].set_name("estop");
    m.locks[0].holder = LockStatus::HOLDER_NONE;
    m
}

/// The description chassisd publishes of `kind` with its default profile.
fn description(kind: RobotKind) -> RobotDescription {
    describe(&kind.entry().defaults())
}

impl Rig {
    /// An engine that has read `description`, judging a robot of its kind.
    fn described(description: &RobotDescription, toml: &str) -> Self {
        let kind = RobotKind::from_id(description.kind).unwrap();
        let config = RawConfig::parse(toml).unwrap().validate().unwrap();
        let mut engine = Engine::new(config, "safety", "chassis/test");
        engine.set_description(description);
        let mut state = ChassisState {
            robot: kind.id(),
            ..ChassisState::default()
        };
        state.system.battery_soc_pct = 80.0;
        // A healthy pack: full, or 2 V above the described low level where no full voltage is
        // described.
        let battery = description.battery;
        state.system.battery_voltage_v = battery.full_v.max(battery.low_v + 2.0) as f32;
        state.ranges.ultrasonic_m = [6.0; 3];
        state.ranges.ir_m = [0.8; 3];
        let mut rig = Self {
            engine,
            state,
            mux: Some(mux_with_estop()),
            now_ms: 0,
            frozen: false,
            wire: false,
        };
        rig.refresh();
        rig
    }

    fn with_config(kind: RobotKind, toml: &str) -> Self {
        Self::described(&description(kind), toml)
    }

    fn new(kind: RobotKind) -> Self {
        Self::with_config(kind, "")
    }

    fn refresh(&mut self) {
        let now = ns(self.now_ms);
        self.state.seq += 1;
        self.state.stamp_ns = now;
        for group in [Group::Motion, Group::System] {
            self.state.touch(group, now);
        }
        if self.wire {
            self.state.touch(Group::Command, now);
        }
        // What each simulated chassis reports: a state of charge from the TITAN's BMS, ranges
        // from the XBot.
        match RobotKind::from_id(self.state.robot) {
            Some(RobotKind::Titan) => self.state.touch(Group::BmsPack, now),
            Some(RobotKind::Xbot) => self.state.touch(Group::Ranges, now),
            _ => {}
        }
    }

    /// Advances to `ms` in 20 ms steps (the state refreshing each step unless frozen) and
    /// returns the last decision with every event on the way.
    fn run_to(&mut self, ms: u64) -> Decision {
        let mut events = Vec::new();
        let mut last = None;
        while self.now_ms < ms || last.is_none() {
            self.now_ms = (self.now_ms + 20).min(ms.max(self.now_ms));
            if !self.frozen {
                self.refresh();
            }
            let mut d = self
                .engine
                .evaluate(ns(self.now_ms), &self.state, self.mux.as_ref());
            events.append(&mut d.events);
            last = Some(d);
        }
        let mut d = last.unwrap();
        d.events = events;
        d
    }

    /// Runs for `ms` more.
    fn run(&mut self, ms: u64) -> Decision {
        self.run_to(self.now_ms + ms)
    }

    /// The service's mux engages or frees the estop lock (holder: a source index or operator).
    fn lock(&mut self, holder: Option<u8>) {
        let m = self.mux.as_mut().unwrap();
        m.seq += 1;
        match holder {
            Some(h) => {
                m.locks[0].held = 1;
                m.locks[0].holder = h;
            }
            None => {
                m.locks[0].held = 0;
                m.locks[0].holder = LockStatus::HOLDER_NONE;
            }
        }
    }
}

fn texts(d: &Decision) -> Vec<&str> {
    d.events.iter().map(|e| e.text.as_str()).collect()
}

#[test]
fn all_is_well_means_heartbeats_and_no_rule_in_force() {
    for robot in RobotKind::ALL {
        let mut rig = Rig::new(robot);
        let d = rig.run(2000);
        assert_eq!(d.command, Command::Heartbeat, "{robot}");
        assert_eq!(d.action, SafetyAction::NONE);
        assert_eq!(d.active_rules, 0);
        assert!(d.events.is_empty(), "{:?}", texts(&d));
        assert_eq!(d.estop, EstopState::FREE);
    }
}

#[test]
fn a_non_warning_fault_stops_at_once_and_releases_after_its_release_time() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.run(100);
    rig.state.system.fault_flags = FaultFlags::MOTOR_2_COMM_LOST;
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(d.action, SafetyAction::STOP);
    assert_eq!(d.active_rules, SafetyRule::bit(SafetyRule::FAULT));
    assert_eq!(texts(&d), ["fault: motor_2_comm_lost"]);
    rig.state.system.fault_flags = 0;
    // Released only after 500 ms clear.
    assert_eq!(rig.run(460).command, Command::Stop);
    let d = rig.run(60);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["fault: cleared"]);
}

#[test]
fn warnings_alone_do_not_stop() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.state.system.fault_flags = FaultFlags::WARNINGS;
    let d = rig.run(1000);
    assert_eq!(d.command, Command::Heartbeat);
    assert!(d.events.is_empty(), "{:?}", texts(&d));
}

#[test]
fn the_battery_triggers_below_its_threshold_after_the_trigger_time_and_releases_above_the_margin() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.state.system.battery_soc_pct = 14.0;
    assert_eq!(rig.run(900).command, Command::Heartbeat, "1 s trigger time");
    let d = rig.run(200);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["battery: 14 % < 15 %"]);
    let e = &d.events[0];
    assert_eq!((e.value, e.threshold), (14.0, 15.0));
    // Above the threshold but inside the margin: still in force.
    rig.state.system.battery_soc_pct = 18.0;
    assert_eq!(rig.run(3000).command, Command::Stop);
    rig.state.system.battery_soc_pct = 20.0;
    assert_eq!(rig.run(900).command, Command::Stop, "1 s release time");
    let d = rig.run(200);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["battery: 20 % ≥ 20 %, released"]);
}

#[test]
fn a_battery_that_dips_shorter_than_the_trigger_time_is_ignored() {
    let mut rig = Rig::new(RobotKind::Xbot);
    for _ in 0..5 {
        rig.state.system.battery_voltage_v = 23.0; // sag while accelerating
        assert_eq!(rig.run(600).command, Command::Heartbeat);
        rig.state.system.battery_voltage_v = 25.0;
        rig.run(100);
    }
}

#[test]
fn a_robot_without_a_bms_is_judged_by_its_own_voltage_threshold() {
    let mut rig = Rig::new(RobotKind::Xbot);
    assert!(!rig.state.is_valid(Group::BmsPack));
    rig.state.system.battery_voltage_v = 23.3;
    let d = rig.run(1100);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["battery: 23.30 V < 23.45 V"]);
    rig.state.system.battery_voltage_v = 23.6; // inside the 0.3 V margin
    assert_eq!(rig.run(2000).command, Command::Stop);
    rig.state.system.battery_voltage_v = 23.8;
    assert_eq!(rig.run(1100).command, Command::Heartbeat);
}

#[test]
fn a_state_that_stops_arriving_stops_the_robot_on_the_monitors_own_clock() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.run(500);
    rig.frozen = true;
    assert_eq!(
        rig.run(200).command,
        Command::Heartbeat,
        "200 ms is allowed"
    );
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(d.active_rules, SafetyRule::bit(SafetyRule::STALE));
    assert!(
        texts(&d)[0].starts_with("stale: no new state for 22"),
        "{:?}",
        texts(&d)
    );
    // It stays stopped however long the silence lasts, and releases 500 ms after it ends.
    assert_eq!(rig.run(10_000).command, Command::Stop);
    rig.frozen = false;
    assert_eq!(rig.run(480).command, Command::Stop);
    let d = rig.run(40);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["stale: fresh state again"]);
}

#[test]
fn a_silent_chassis_or_a_lost_bus_stops_the_robot_though_the_service_still_publishes() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.run(200);
    rig.state.link_flags = LinkFlags::BUS_DOWN;
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["stale: bus_down"]);
    rig.state.link_flags = 0;
    assert_eq!(rig.run(600).command, Command::Heartbeat);

    // Samples keep coming (the service refreshes them), but no frame from the chassis: its
    // stamp stops moving.
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.run(200);
    let stamp = rig.state.stamp_ns;
    let mut d = rig.run(0);
    for _ in 0..20 {
        rig.now_ms += 20;
        rig.refresh();
        rig.state.stamp_ns = stamp;
        d = rig
            .engine
            .evaluate(ns(rig.now_ms), &rig.state, rig.mux.as_ref());
        if d.command == Command::Stop {
            break;
        }
    }
    assert_eq!(d.command, Command::Stop);
    assert!(
        d.events[0].text.starts_with("stale: chassis silent for 3"),
        "{:?}",
        texts(&d)
    );
}

#[test]
fn a_state_that_never_heard_the_chassis_is_stale() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.state = ChassisState::default();
    rig.frozen = true;
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop);
}

#[test]
fn an_obstacle_ahead_in_the_slow_zone_limits_only_the_forward_speed() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.run(100);
    rig.state.ranges.ultrasonic_m = [0.7, 0.6, 0.7];
    let d = rig.run(20);
    assert_eq!(d.action, SafetyAction::SLOW);
    let Command::Limit(e) = d.command else {
        panic!("{:?}", d.command)
    };
    assert_eq!(e.forward_mps, 0.15);
    assert_eq!(e.reverse_mps, SafetyStatus::UNLIMITED);
    assert_eq!((e.lateral_mps, e.angular_radps), (0.15, 0.5));
    assert_eq!(texts(&d), ["ultrasonic: slow zone, 0.60 m < 0.80 m"]);
}

#[test]
fn an_obstacle_ahead_in_the_stop_zone_blocks_forward_motion_but_lets_the_robot_reverse() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.run(100);
    rig.state.ranges.ultrasonic_m = [0.35, 0.3, 0.35];
    let d = rig.run(20);
    let Command::Limit(e) = d.command else {
        panic!("{:?}", d.command)
    };
    assert_eq!(e.forward_mps, 0.0);
    assert_eq!(e.reverse_mps, SafetyStatus::UNLIMITED);
    assert_eq!(d.envelope, e);
    assert_eq!(d.active_rules, SafetyRule::bit(SafetyRule::ULTRASONIC));
    assert_eq!(texts(&d), ["ultrasonic: stop zone, 0.30 m < 0.35 m"]);
    // A real request through this envelope: forward clamps to 0, reverse passes.
    let r = d.command.request();
    assert!(r.is_limit() && chassis_client::ValidRequest::try_from(r).is_ok());
    assert_eq!(0.3f32.clamp(-r.limit_reverse_mps, r.limit_forward_mps), 0.0);
    assert_eq!(
        (-0.2f32).clamp(-r.limit_reverse_mps, r.limit_forward_mps),
        -0.2
    );
}

#[test]
fn an_obstacle_behind_blocks_reversing_but_not_driving_forward() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.state.ranges.ir_m = [0.14, 0.1, 0.14];
    let d = rig.run(40);
    let Command::Limit(e) = d.command else {
        panic!("{:?}", d.command)
    };
    assert_eq!(
        (e.forward_mps, e.reverse_mps),
        (SafetyStatus::UNLIMITED, 0.0)
    );
    rig.state.ranges.ir_m = [0.25; 3];
    let d = rig.run(400);
    let Command::Limit(e) = d.command else {
        panic!("{:?}", d.command)
    };
    assert_eq!(
        (e.forward_mps, e.reverse_mps),
        (SafetyStatus::UNLIMITED, 0.15)
    );
}

#[test]
fn obstacles_on_both_sides_block_both_directions_but_still_allow_a_slow_turn() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.state.ranges.ultrasonic_m = [0.2; 3];
    rig.state.ranges.ir_m = [0.1; 3];
    let d = rig.run(40);
    assert_eq!(
        d.command,
        Command::Limit(Envelope {
            forward_mps: 0.0,
            reverse_mps: 0.0,
            lateral_mps: 0.15,
            angular_radps: 0.5
        })
    );
}

#[test]
fn range_zones_release_only_beyond_their_hysteresis_and_after_the_release_time() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.state.ranges.ultrasonic_m = [0.3; 3];
    rig.run(40);
    // Just outside the stop zone but inside its 5 cm hysteresis: still blocked.
    rig.state.ranges.ultrasonic_m = [0.38; 3];
    let d = rig.run(2000);
    assert!(matches!(d.command, Command::Limit(e) if e.forward_mps == 0.0));
    rig.state.ranges.ultrasonic_m = [0.41; 3];
    let d = rig.run(280);
    assert!(
        matches!(d.command, Command::Limit(e) if e.forward_mps == 0.0),
        "300 ms release time"
    );
    let d = rig.run(40);
    assert!(matches!(d.command, Command::Limit(e) if e.forward_mps == 0.15));
    assert_eq!(
        texts(&d),
        ["ultrasonic: back to the slow zone, 0.41 m ≥ 0.40 m"]
    );
    // A noisy sample inside the slow zone's hysteresis resets nothing; clear beyond 0.85 m.
    rig.state.ranges.ultrasonic_m = [0.84; 3];
    assert!(matches!(rig.run(1000).command, Command::Limit(_)));
    rig.state.ranges.ultrasonic_m = [6.0; 3];
    let d = rig.run(320);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["ultrasonic: clear, 6.00 m ≥ 0.85 m"]);
    // Going back in is immediate.
    rig.state.ranges.ultrasonic_m = [0.2; 3];
    assert!(matches!(rig.run(20).command, Command::Limit(e) if e.forward_mps == 0.0));
}

#[test]
fn one_noisy_clear_reading_does_not_release_a_zone() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.state.ranges.ultrasonic_m = [0.3; 3];
    rig.run(40);
    for _ in 0..10 {
        rig.state.ranges.ultrasonic_m = [6.0; 3];
        rig.run(100);
        rig.state.ranges.ultrasonic_m = [0.3; 3];
        let d = rig.run(20);
        assert!(matches!(d.command, Command::Limit(e) if e.forward_mps == 0.0));
    }
}

#[test]
fn robots_without_ranges_are_never_limited_by_the_range_rules() {
    for robot in [RobotKind::Titan, RobotKind::ScoutMini] {
        let mut rig = Rig::new(robot);
        // Zeros in fields the robot never reported are not readings.
        rig.state.ranges = Default::default();
        let d = rig.run(1000);
        assert_eq!(d.command, Command::Heartbeat);
    }
}

#[test]
fn ranges_that_stop_updating_count_as_obstacles_in_both_directions() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.run(100);
    let stamp = rig.state.group_stamp_ns[Group::Ranges.index()];
    let mut d = rig.run(0);
    for _ in 0..20 {
        rig.now_ms += 20;
        rig.refresh();
        rig.state.group_stamp_ns[Group::Ranges.index()] = stamp;
        d = rig
            .engine
            .evaluate(ns(rig.now_ms), &rig.state, rig.mux.as_ref());
    }
    let Command::Limit(e) = d.command else {
        panic!("{:?}", d.command)
    };
    assert_eq!((e.forward_mps, e.reverse_mps), (0.0, 0.0));
}

#[test]
fn a_non_finite_range_reading_is_an_obstacle() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.state.ranges.ultrasonic_m = [6.0, f32::NAN, 6.0];
    let d = rig.run(40);
    assert!(matches!(d.command, Command::Limit(e) if e.forward_mps == 0.0));
}

#[test]
fn a_speed_above_the_limit_stops_and_releases_below_the_margin() {
    // The XBot's description: 1.5 m/s either way; × 1.1 + 0.05 m/s = 1.7 m/s.
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.state.motion.linear_mps = -1.69;
    assert_eq!(
        rig.run(1000).command,
        Command::Heartbeat,
        "inside the margin"
    );
    rig.state.motion.linear_mps = -1.8;
    assert_eq!(
        rig.run(180).command,
        Command::Heartbeat,
        "200 ms trigger time"
    );
    let d = rig.run(40);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["speed: 1.80 m/s reverse > 1.70 m/s"]);
    rig.state.motion.linear_mps = 1.6;
    assert_eq!(
        rig.run(2000).command,
        Command::Stop,
        "inside the release margin"
    );
    rig.state.motion.linear_mps = 1.4;
    let d = rig.run(520);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["speed: 1.40 m/s < 1.50 m/s, released"]);
}

#[test]
fn the_speed_limit_follows_the_descriptions_effective_limits_per_direction() {
    let mut d = description(RobotKind::Hunter);
    // chassisd's [mux.limits]: 0.5 m/s forward, the driver's 1.5 m/s reverse.
    d.configured_limits.forward_mps = 0.5;
    let mut rig = Rig::described(&d, "");
    let levels = rig.engine.levels();
    assert!((levels.speed_forward_mps.value.unwrap() - 0.6).abs() < 1e-9);
    assert!((levels.speed_reverse_mps.value.unwrap() - 1.7).abs() < 1e-9);
    rig.state.motion.linear_mps = -1.0;
    assert_eq!(
        rig.run(1000).command,
        Command::Heartbeat,
        "reverse: 1.7 m/s"
    );
    rig.state.motion.linear_mps = 0.7;
    let d = rig.run(300);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["speed: 0.70 m/s > 0.60 m/s"]);
}

#[test]
fn a_newer_description_replaces_the_levels() {
    // A SCOUT MINI heard speaking V1 (5 m/s full scale), then described again as V2 (3 m/s).
    let mut rig = Rig::new(RobotKind::ScoutMini);
    rig.state.motion.linear_mps = 4.0;
    assert_eq!(rig.run(1000).command, Command::Heartbeat);
    let v2 = describe(
        &RobotKind::ScoutMini
            .entry()
            .default_profile(Some(chassis_protocols::Protocol::V2))
            .unwrap(),
    );
    assert_eq!(v2.robot_limits.forward_mps, 3.0);
    rig.engine.set_description(&v2);
    let d = rig.run(300);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["speed: 4.00 m/s > 3.35 m/s"]);
}

#[test]
fn an_explicit_level_in_the_file_wins_over_the_description() {
    let mut rig = Rig::with_config(
        RobotKind::Xbot,
        "[rules.speed]\nmax_linear_mps = 1.0\n[rules.battery]\nmin_voltage_v = 24.0\n",
    );
    let levels = rig.engine.levels().clone();
    assert_eq!(levels.speed_forward_mps.value, Some(1.0));
    assert_eq!(levels.speed_reverse_mps.value, Some(1.0));
    assert!(matches!(levels.speed_forward_mps.origin, Origin::Config(_)));
    // What the description gives is kept for --print-config.
    let (described, _) = levels.speed_forward_mps.described.clone().unwrap();
    assert!((described - 1.7).abs() < 1e-9);
    assert_eq!(levels.battery_voltage_v.value, Some(24.0));
    rig.state.system.battery_voltage_v = 23.8;
    rig.state.motion.linear_mps = 1.2;
    let d = rig.run(1100);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(
        texts(&d),
        ["speed: 1.20 m/s > 1.00 m/s", "battery: 23.80 V < 24.00 V"]
    );
}

#[test]
fn without_a_description_only_the_files_levels_are_in_force_and_the_rest_is_said() {
    let config = RawConfig::parse("[rules.battery]\nmin_voltage_v = 24.0\n")
        .unwrap()
        .validate()
        .unwrap();
    let engine = Engine::new(config, "safety", "chassis/test");
    let levels = engine.levels();
    assert_eq!(levels.speed_forward_mps.value, None);
    assert_eq!(levels.battery_voltage_v.value, Some(24.0));
    let warnings = levels.warnings(engine.config(), "chassis/test");
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(
        warnings[0].starts_with("speed rule: no forward or reverse limit for chassis/test"),
        "{warnings:?}"
    );
}

#[test]
fn a_description_without_a_level_a_rule_needs_is_said_naming_the_rule_and_the_robot() {
    let mut d = description(RobotKind::Bunker);
    d.battery.low_v = f64::NAN;
    d.battery.critical_v = f64::NAN;
    d.robot_limits.reverse_mps = f64::NAN;
    let mut rig = Rig::described(&d, "");
    let warnings = rig
        .engine
        .levels()
        .warnings(rig.engine.config(), "chassis/test");
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(
        warnings[0].starts_with("speed rule: no reverse limit for chassis/test (AgileX BUNKER"),
        "{warnings:?}"
    );
    assert!(
        warnings[1].starts_with("battery rule: no level for chassis/test (AgileX BUNKER"),
        "{warnings:?}"
    );
    // At run time too: the robot reports a voltage, and nothing judges it.
    let d = rig.run(20);
    assert_eq!(d.notices.len(), 1, "{:?}", d.notices);
    assert!(d.notices[0].starts_with("battery rule: chassis/test reports its"));
}

#[test]
fn the_battery_rule_says_which_reading_it_judges() {
    let mut rig = Rig::new(RobotKind::Titan);
    let d = rig.run(20);
    assert_eq!(d.infos.len(), 1, "{:?}", d.infos);
    assert!(
        d.infos[0]
            .starts_with("battery: judging chassis/test by its state of charge (below 15.0 %"),
        "{:?}",
        d.infos
    );
    assert!(rig.run(1000).infos.is_empty(), "said once");
    let mut rig = Rig::new(RobotKind::RangerMini);
    // A protocol-V2 chassis reports a state of charge, but its description gives no level for
    // one: the voltage is judged.
    rig.state.touch(Group::BmsPack, ns(rig.now_ms));
    let d = rig.run(20);
    assert!(
        d.infos[0].starts_with("battery: judging chassis/test by its voltage (below 23.5 V"),
        "{:?}",
        d.infos
    );
    assert!(
        d.infos[0].contains("reports a state of charge"),
        "{:?}",
        d.infos
    );
}

#[test]
fn a_latch_engages_the_lock_with_its_rules_stop_category() {
    let mut rig = Rig::with_config(RobotKind::Titan, "[monitor.categories]\nbumper = 0\n");
    rig.run(100);
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    let d = rig.run(20);
    assert_eq!(d.command, Command::StopAndLock(1, Some(0)));
    assert_eq!(
        d.command.request().flags,
        chassis_client::RequestFlags::CATEGORY_0
    );
    // Only a latch engages the lock: a category for a rule that stops is refused.
    let refused = |toml: &str| {
        toml::from_str::<crate::config::RawConfig>(toml)
            .unwrap()
            .validate()
            .unwrap_err()
            .to_string()
    };
    assert!(
        refused("[monitor.categories]\nfault = 1\n").contains("only a rule whose action is latch")
    );
    assert!(refused("[monitor.categories]\nbumper = 3\n").contains("0, 1 or 2"));
    assert!(refused("[monitor.categories]\nwheels = 1\n").contains("is not a rule"));
}

#[test]
fn the_bumper_latches_the_estop_until_the_operator_releases_it() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.run(100);
    rig.state.system.fault_flags = FaultFlags::BUMPER | FaultFlags::BODY_EXCEPTION;
    let d = rig.run(20);
    assert_eq!(d.command, Command::StopAndLock(1, None));
    assert_eq!(d.action, SafetyAction::LATCH);
    // The TITAN reports a body exception with any fault bit: the fault rule stops as well.
    assert_eq!(texts(&d), ["fault: body_exception", "bumper: pressed"]);
    // Until the mux shows the lock held, every request engages it.
    assert_eq!(rig.run(60).command, Command::StopAndLock(1, None));
    rig.lock(Some(0));
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop, "held: no more lock bits");
    assert_eq!(d.estop, EstopState::HELD_BY_MONITOR);
    // The bumper is released; the latch holds.
    rig.state.system.fault_flags = 0;
    let d = rig.run(5000);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(d.action, SafetyAction::LATCH);
    assert_eq!(texts(&d), ["fault: cleared", "bumper: released"]);
    assert_eq!(d.active_rules, SafetyRule::bit(SafetyRule::BUMPER));
    // `chassis control estop-release`: the mux shows the lock free.
    rig.lock(None);
    let d = rig.run(20);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["bumper: estop released by the operator"]);
    assert_eq!(d.active_rules, 0);
    // The next contact latches again.
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    assert_eq!(rig.run(20).command, Command::StopAndLock(1, None));
}

#[test]
fn a_release_while_the_bumper_is_still_pressed_does_not_relatch_until_it_is_pressed_again() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    rig.run(40);
    rig.lock(Some(0));
    rig.run(100);
    rig.lock(None);
    let d = rig.run(20);
    assert_eq!(d.command, Command::Heartbeat, "the operator took over");
    assert_eq!(d.acknowledged_rules, SafetyRule::bit(SafetyRule::BUMPER));
    assert!(texts(&d)[0].contains("still present"), "{:?}", texts(&d));
    assert_eq!(rig.run(3000).command, Command::Heartbeat);
    // It clears (500 ms), is re-armed, and the next press latches.
    rig.state.system.fault_flags = 0;
    let d = rig.run(600);
    assert_eq!(texts(&d), ["bumper: released; latch re-armed"]);
    assert_eq!(d.acknowledged_rules, 0);
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    assert_eq!(rig.run(20).command, Command::StopAndLock(1, None));
}

#[test]
fn a_latch_without_a_mux_status_stops_until_the_lock_can_be_engaged() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.mux = None;
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    let d = rig.run(40);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(d.action, SafetyAction::LATCH);
    assert_eq!(d.estop, EstopState::UNKNOWN);
    rig.mux = Some(mux_with_estop());
    assert_eq!(rig.run(20).command, Command::StopAndLock(1, None));
}

#[test]
fn a_restarted_service_gets_the_latched_lock_engaged_again() {
    let mut rig = Rig::new(RobotKind::Titan);
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    rig.run(40);
    rig.lock(Some(0));
    assert_eq!(rig.run(100).command, Command::Stop);
    // A new chassisd: its mux starts again at seq 1 with every lock free.
    rig.mux = Some(mux_with_estop());
    let d = rig.run(20);
    assert_eq!(d.command, Command::StopAndLock(1, None));
    assert_eq!(d.notices.len(), 1, "{:?}", d.notices);
}

#[test]
fn without_an_estop_lock_a_latching_rule_acts_as_a_stop() {
    let mut rig = Rig::new(RobotKind::Titan);
    let m = rig.mux.as_mut().unwrap();
    m.lock_count = 0;
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(d.action, SafetyAction::STOP);
    assert_eq!(d.notices.len(), 1);
    rig.state.system.fault_flags = 0;
    let d = rig.run(600);
    assert_eq!(d.command, Command::Heartbeat);
    assert!(d.notices.is_empty(), "said once");
}

#[test]
fn the_operator_estop_latches_and_an_operator_lock_is_reported() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.run(100);
    assert!(rig.engine.request_operator_estop());
    let d = rig.run(20);
    assert_eq!(d.command, Command::StopAndLock(1, None));
    assert_eq!(texts(&d), ["operator: e-stop (SIGUSR1)"]);
    rig.lock(Some(0));
    let d = rig.run(1000);
    assert_eq!(d.command, Command::Stop);
    assert!(d.events.is_empty(), "{:?}", texts(&d));
    rig.lock(None);
    assert_eq!(rig.run(20).command, Command::Heartbeat);
    // `chassis control estop`: the operator engages the lock in the service.
    rig.lock(Some(LockStatus::HOLDER_OPERATOR));
    let d = rig.run(20);
    assert_eq!(d.estop, EstopState::HELD_BY_OPERATOR);
    assert_eq!(
        d.command,
        Command::Heartbeat,
        "the lock itself holds the robot"
    );
}

#[test]
fn the_strictest_rule_wins() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.state.ranges.ultrasonic_m = [0.5; 3];
    assert!(matches!(rig.run(40).command, Command::Limit(_)));
    rig.state.system.fault_flags = FaultFlags::MOTOR_DRIVER_ERROR;
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(
        d.active_rules,
        SafetyRule::bit(SafetyRule::FAULT) | SafetyRule::bit(SafetyRule::ULTRASONIC)
    );
    assert_eq!(d.envelope, Envelope::ZERO);
}

#[test]
fn a_slow_action_publishes_the_slow_envelope_in_every_direction() {
    let mut rig = Rig::with_config(RobotKind::Titan, "[rules.battery]\naction = \"slow\"\n");
    rig.state.system.battery_soc_pct = 5.0;
    let d = rig.run(1100);
    assert_eq!(
        d.command,
        Command::Limit(Envelope {
            forward_mps: 0.15,
            reverse_mps: 0.15,
            lateral_mps: 0.15,
            angular_radps: 0.5
        })
    );
}

#[test]
fn a_range_rule_set_to_stop_stops_inside_its_stop_zone_only() {
    let mut rig = Rig::with_config(RobotKind::Xbot, "[rules.ultrasonic]\naction = \"stop\"\n");
    rig.state.ranges.ultrasonic_m = [0.5; 3];
    assert!(matches!(rig.run(40).command, Command::Limit(_)));
    rig.state.ranges.ultrasonic_m = [0.2; 3];
    assert_eq!(rig.run(20).command, Command::Stop);
}

#[test]
fn disabled_rules_never_trigger() {
    let mut rig = Rig::with_config(
        RobotKind::Xbot,
        "[rules.ultrasonic]\nenabled = false\n[rules.ir]\nenabled = false\n\
         [rules.stale]\nenabled = false\n[rules.operator]\nenabled = false\n",
    );
    rig.state.ranges.ultrasonic_m = [0.1; 3];
    rig.frozen = true;
    assert!(!rig.engine.request_operator_estop());
    let d = rig.run(2000);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(
        rig.engine.enabled_rules() & SafetyRule::bit(SafetyRule::ULTRASONIC),
        0
    );
}

#[test]
fn the_status_reports_the_decision_counts_and_the_last_event() {
    let mut rig = Rig::new(RobotKind::Xbot);
    for _ in 0..3 {
        rig.state.ranges.ultrasonic_m = [0.3; 3];
        rig.run(40);
        rig.state.ranges.ultrasonic_m = [6.0; 3];
        rig.run(400);
    }
    rig.state.ranges.ultrasonic_m = [0.6; 3];
    let d = rig.run(20);
    let mut status = SafetyStatus::default();
    rig.engine.fill_status(&d, &mut status);
    assert_eq!(status.action, SafetyAction::SLOW);
    assert!(status.is_active(SafetyRule::ULTRASONIC));
    assert_eq!(status.limit_forward_mps, 0.15);
    // Three stop-zone entries and one slow-zone entry.
    assert_eq!(status.trigger_count(SafetyRule::ULTRASONIC), 4);
    assert_eq!(status.last_trigger_ns[4], ns(rig.now_ms));
    assert_eq!(status.last_rule, SafetyRule::ULTRASONIC);
    assert_eq!(status.last_event, SafetyEvent::TRIGGER);
    assert_eq!(status.last_text(), "ultrasonic: slow zone, 0.60 m < 0.80 m");
    assert_eq!(status.enabled_rules, (1 << SafetyRule::COUNT) - 1);
    assert_eq!(status.estop, EstopState::FREE);
}

/// Every robot of the registry, end to end on simulated time: its default description, its
/// driver against its simulated firmware, and the engine judging what the driver reports. A
/// robot whose description lacks a level, or whose chassis reports no reading the level is
/// for, fails here.
#[test]
fn every_robot_of_the_registry_has_a_speed_rule_and_a_battery_rule() {
    use chassis_protocols::{Injection, Timestamp, pair::Pair};
    use std::time::Duration;

    /// Runs the pair for `ms` in 20 ms steps, evaluating the engine on what the driver reports;
    /// returns the rules that were in force at some step and every event text.
    fn watch<D: chassis_protocols::Driver, F: chassis_protocols::Firmware>(
        pair: &mut Pair<D, F>,
        engine: &mut Engine,
        ms: u64,
    ) -> (u32, Vec<String>) {
        let (mut active, mut texts) = (0, Vec::new());
        for _ in 0..ms / 20 {
            pair.run_for(Duration::from_millis(20));
            let now = pair.now().as_nanos();
            let d = engine.evaluate(now, pair.driver.state(), None);
            active |= d.active_rules;
            texts.extend(d.events.into_iter().map(|e| e.text));
        }
        (active, texts)
    }

    for kind in RobotKind::ALL {
        let entry = kind.entry();
        let profile = entry.defaults();
        let description = describe(&profile);
        let config = RawConfig::default().validate().unwrap();
        let mut engine = Engine::new(config, "safety", "chassis/test");
        engine.set_description(&description);
        let warnings = engine.levels().warnings(engine.config(), "chassis/test");
        assert!(warnings.is_empty(), "{kind}: {warnings:?}");

        let mut pair = entry.simulated_pair(&profile, Timestamp::from_millis(1_000));
        let (active, texts) = watch(&mut pair, &mut engine, 2000);
        let both = SafetyRule::bit(SafetyRule::SPEED) | SafetyRule::bit(SafetyRule::BATTERY);
        assert_eq!(active & both, 0, "{kind} at rest: {texts:?}");

        // A runaway past the description's limit.
        let limit = description.effective_limits().forward_mps;
        assert!(pair.inject(Injection::Runaway(Some(limit * 1.5))), "{kind}");
        let (active, texts) = watch(&mut pair, &mut engine, 2000);
        assert_ne!(
            active & SafetyRule::bit(SafetyRule::SPEED),
            0,
            "{kind}: no speed rule at {} m/s past a {limit} m/s limit: {texts:?}",
            limit * 1.5
        );
        assert!(pair.inject(Injection::Runaway(None)), "{kind}");
        watch(&mut pair, &mut engine, 2000);

        // A flat battery, as the robot reports it (state of charge or voltage).
        assert!(pair.inject(Injection::Battery { soc_pct: 5.0 }), "{kind}");
        let (active, texts) = watch(&mut pair, &mut engine, 3000);
        assert_ne!(
            active & SafetyRule::bit(SafetyRule::BATTERY),
            0,
            "{kind}: no battery rule at 5 % ({:?} V reported): {texts:?}",
            pair.driver.state().system.battery_voltage_v
        );
    }
}

/// An XBot as chassisd describes it (its `[mux.limits]` accelerate at 2 m/s²), its driver
/// reporting the command on the wire, drive power on, in command mode.
fn driving(toml: &str) -> Rig {
    let mut d = description(RobotKind::Xbot);
    d.configured_limits.linear_accel_mps2 = 2.0;
    let mut rig = Rig::described(&d, toml);
    rig.wire = true;
    rig.state.system.power_enabled = 1;
    rig.state.system.control_mode = ControlMode::COMMAND;
    rig
}

impl Rig {
    /// `command` m/s on the wire, `measured` m/s measured.
    fn drive(&mut self, command: f32, measured: f32) {
        self.state.command.linear_mps = command;
        self.state.motion.linear_mps = measured;
    }

    fn status(&self, d: &Decision) -> SafetyStatus {
        let mut status = SafetyStatus::default();
        self.engine.fill_status(d, &mut status);
        status
    }
}

/// `kind` as chassisd describes it, yaw accelerating at 3 rad/s², driving straight at 0.3 m/s.
fn turning(kind: RobotKind) -> Rig {
    let mut d = description(kind);
    d.configured_limits.linear_accel_mps2 = 2.0;
    d.configured_limits.angular_accel_radps2 = 3.0;
    let mut rig = Rig::described(&d, "");
    rig.wire = true;
    rig.state.system.power_enabled = 1;
    rig.state.system.control_mode = ControlMode::COMMAND;
    rig.drive(0.3, 0.3);
    rig
}

impl Rig {
    /// `command` rad/s on the wire, `measured` rad/s measured.
    fn turn(&mut self, command: f32, measured: f32) {
        self.state.command.angular_radps = command;
        self.state.motion.angular_radps = measured;
    }
}

#[test]
fn a_yaw_rate_beyond_or_against_the_command_latches_where_the_wire_carries_one() {
    let mut rig = turning(RobotKind::Xbot);
    rig.turn(0.5, 0.5);
    assert_eq!(rig.run(2000).command, Command::Heartbeat);
    // 0.5 rad/s × 1.2 + 0.1 rad/s = 0.7 rad/s.
    rig.turn(0.5, 0.9);
    let d = rig.run(300);
    assert!(matches!(d.command, Command::StopAndLock(..)), "{d:?}");
    assert_eq!(
        texts(&d),
        ["runaway: 0.90 rad/s, commands allow 0.70 rad/s"]
    );

    let mut rig = turning(RobotKind::Xbot);
    rig.turn(0.5, 0.5);
    rig.run(2000);
    rig.turn(0.5, -0.4);
    let d = rig.run(300);
    assert!(matches!(d.command, Command::StopAndLock(..)), "{d:?}");
    assert_eq!(
        texts(&d),
        ["direction: -0.40 rad/s against a 0.50 rad/s command"]
    );
}

#[test]
fn a_steering_robots_yaw_rate_is_not_judged() {
    // TITAN steers its wheels: the wire carries a steer angle, not a yaw rate.
    let mut rig = turning(RobotKind::Titan);
    rig.turn(0.0, 0.9);
    let d = rig.run(2000);
    assert_eq!(d.command, Command::Heartbeat, "{:?}", texts(&d));
}

#[test]
fn moving_while_commanded_still_latches_as_a_runaway() {
    let mut rig = driving("");
    rig.drive(0.0, 0.0);
    assert_eq!(rig.run(1000).command, Command::Heartbeat);
    rig.drive(0.0, 0.3);
    assert_eq!(
        rig.run(180).command,
        Command::Heartbeat,
        "200 ms trigger time"
    );
    let d = rig.run(40);
    assert!(matches!(d.command, Command::StopAndLock(..)), "{d:?}");
    assert_eq!(texts(&d), ["runaway: 0.30 m/s, commands allow 0.05 m/s"]);
}

#[test]
fn faster_than_commanded_beyond_the_margin_is_a_runaway_and_within_it_is_not() {
    let mut rig = driving("");
    // 0.5 m/s × 1.2 + 0.05 m/s = 0.65 m/s.
    rig.drive(0.5, 0.64);
    assert_eq!(rig.run(2000).command, Command::Heartbeat);
    rig.drive(0.5, 0.7);
    let d = rig.run(300);
    assert!(matches!(d.command, Command::StopAndLock(..)), "{d:?}");
    assert_eq!(texts(&d), ["runaway: 0.70 m/s, commands allow 0.65 m/s"]);
}

#[test]
fn a_robot_that_lags_and_brakes_at_its_acceleration_is_no_runaway() {
    let mut rig = driving("");
    rig.drive(1.0, 1.0);
    rig.run(1000);
    // The wire drops to zero; the robot keeps its speed 300 ms, then brakes at 2 m/s².
    let mut events = Vec::new();
    for step in 0..100u16 {
        let t = f32::from(step) * 0.02;
        let measured = if t < 0.3 {
            1.0
        } else {
            (1.0 - 2.0 * (t - 0.3)).max(0.0)
        };
        rig.drive(0.0, measured);
        let d = rig.run(20);
        assert_eq!(d.command, Command::Heartbeat, "at {t} s: {:?}", texts(&d));
        events.extend(d.events);
    }
    assert!(events.is_empty(), "{events:?}");
}

#[test]
fn motion_against_the_command_latches_and_a_lagging_reversal_does_not() {
    let mut rig = driving("");
    rig.drive(0.5, 0.5);
    rig.run(1000);
    rig.drive(-0.5, 0.5);
    assert_eq!(rig.run(300).command, Command::Heartbeat, "still reversing");
    rig.drive(-0.5, -0.5);
    assert_eq!(rig.run(2000).command, Command::Heartbeat);
    rig.drive(0.5, 0.5);
    rig.run(2000);
    rig.drive(0.5, -0.3);
    let d = rig.run(300);
    assert!(matches!(d.command, Command::StopAndLock(..)), "{d:?}");
    assert_eq!(
        texts(&d),
        ["direction: -0.30 m/s against a 0.50 m/s command"]
    );
    assert!(rig.status(&d).is_active(SafetyRule::DIRECTION));
}

#[test]
fn a_chassis_that_does_not_follow_stops_after_the_time_it_needs_and_names_the_cause() {
    let mut rig = driving("");
    rig.state.system.control_mode = ControlMode::STANDBY;
    // From 0 to 0.5 m/s and back within reach at 2 m/s², and the 500 ms lag: 1 s.
    rig.drive(0.5, 0.0);
    assert_eq!(rig.run(960).command, Command::Heartbeat);
    let d = rig.run(60);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["following: 0.00 of 0.50 m/s, standby"]);
    let status = rig.status(&d);
    assert!(status.is_active(SafetyRule::FOLLOWING));
    assert_eq!(status.unfollowed, Unfollowed::STANDBY);
    // The command drops to zero: released after its release time, the cause with it.
    rig.drive(0.0, 0.0);
    assert_eq!(rig.run(960).command, Command::Stop);
    let d = rig.run(60);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["following: released"]);
    assert_eq!(rig.status(&d).unfollowed, Unfollowed::NONE);
}

#[test]
fn a_slipping_chassis_does_not_follow_and_one_that_keeps_up_does() {
    let mut rig = driving("");
    rig.drive(1.0, 0.3);
    assert_eq!(
        rig.run(3000).command,
        Command::Heartbeat,
        "30 % of the command"
    );
    rig.drive(1.0, 0.2);
    let d = rig.run(2000);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(rig.status(&d).unfollowed, Unfollowed::UNREPORTED);
}

#[test]
fn the_cause_of_not_following_is_what_the_chassis_reports_most_telling_first() {
    /// What the chassis reports, and the cause it names.
    type Case = (fn(&mut ChassisState), u8);
    let cases: [Case; 9] = [
        (|_| {}, Unfollowed::UNREPORTED),
        (
            |s| s.link_flags = LinkFlags::CHASSIS_SILENT,
            Unfollowed::BUS_SILENT,
        ),
        (
            |s| s.system.fault_flags = FaultFlags::EMERGENCY_STOP | FaultFlags::MOTOR_DRIVER_ERROR,
            Unfollowed::CHASSIS_ESTOP,
        ),
        (
            |s| s.link_flags = LinkFlags::RC_AUTHORITY,
            Unfollowed::REMOTE_CONTROL,
        ),
        (
            |s| s.system.control_mode = ControlMode::STANDBY,
            Unfollowed::STANDBY,
        ),
        (
            |s| s.system.control_mode = ControlMode::SERIAL,
            Unfollowed::SERIAL_MODE,
        ),
        (
            |s| s.system.fault_flags = FaultFlags::MOTOR_2_COMM_LOST,
            Unfollowed::DRIVER_FAULT,
        ),
        (|s| s.system.power_enabled = 0, Unfollowed::DRIVERS_DISABLED),
        (
            |s| s.system.parking_brake_engaged = 1,
            Unfollowed::PARKING_BRAKE,
        ),
    ];
    for (report, cause) in cases {
        let mut rig = driving("");
        report(&mut rig.state);
        rig.drive(0.5, 0.0);
        let d = rig.run(1100);
        let status = rig.status(&d);
        assert!(status.is_active(SafetyRule::FOLLOWING), "{cause}");
        assert_eq!(
            Unfollowed::name(status.unfollowed),
            Unfollowed::name(cause),
            "{:?}",
            texts(&d)
        );
        assert!(!Unfollowed::text(cause).is_empty());
    }
}

#[test]
fn without_an_acceleration_the_plausibility_rules_say_so_and_do_not_judge() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.wire = true;
    rig.drive(0.0, 0.5);
    let d = rig.run(20);
    assert_eq!(
        d.notices,
        [
            "runaway, direction and following rules: no linear acceleration is known for \
             chassis/test: they do not judge; set [rules.plausibility] linear_accel_mps2"
        ]
    );
    let d = rig.run(2000);
    assert!(d.notices.is_empty());
    assert_eq!(d.command, Command::Heartbeat);
    // The file's acceleration: judged.
    let mut rig = Rig::with_config(
        RobotKind::Xbot,
        "[rules.plausibility]\nlinear_accel_mps2 = 1.0\n",
    );
    rig.wire = true;
    rig.drive(0.0, 0.5);
    assert!(matches!(rig.run(300).command, Command::StopAndLock(..)));
}

#[test]
fn disabled_plausibility_rules_do_not_judge() {
    let mut rig = driving(
        "[rules.runaway]\nenabled = false\n[rules.direction]\nenabled = false\n\
         [rules.following]\nenabled = false\n",
    );
    rig.drive(0.5, -1.0);
    assert_eq!(rig.run(3000).command, Command::Heartbeat);
}

impl Rig {
    /// The mux caps every source to `mps` (a planner's limit).
    fn speed_limit(&mut self, mps: f32) {
        let m = self.mux.as_mut().unwrap();
        m.seq += 1;
        m.speed_limit_mps = mps;
        m.speed_limit_holder = 2;
    }
}

#[test]
fn over_the_speed_limit_beyond_the_margin_for_longer_than_the_bound_stops() {
    let mut rig = Rig::new(RobotKind::Xbot);
    rig.state.motion.linear_mps = 1.0;
    assert_eq!(rig.run(2000).command, Command::Heartbeat, "no limit set");
    // 0.5 m/s + the 0.1 m/s margin.
    rig.speed_limit(0.5);
    rig.state.motion.linear_mps = -0.59;
    assert_eq!(
        rig.run(3000).command,
        Command::Heartbeat,
        "inside the margin"
    );
    rig.state.motion.linear_mps = -0.7;
    assert_eq!(
        rig.run(980).command,
        Command::Heartbeat,
        "the robot has 1000 ms to brake down to a lowered limit"
    );
    let d = rig.run(40);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(
        texts(&d),
        ["limit: 0.70 m/s > the speed limit + margin, 0.60 m/s"]
    );
    let status = rig.status(&d);
    assert_eq!(status.why(), "STOP by limit");
    assert!(status.is_active(SafetyRule::LIMIT));
    rig.state.motion.linear_mps = 0.4;
    let d = rig.run(520);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["limit: 0.40 m/s ≤ 0.60 m/s, released"]);
}

#[test]
fn the_speed_limit_rule_takes_its_margin_and_bound_from_the_file_and_can_be_disabled() {
    let mut rig = Rig::with_config(
        RobotKind::Titan,
        "[rules.limit]\nmargin_mps = 0.0\ntrigger_ms = 200\n",
    );
    rig.speed_limit(0.3);
    rig.state.motion.linear_mps = 0.35;
    assert_eq!(rig.run(180).command, Command::Heartbeat);
    assert_eq!(rig.run(40).command, Command::Stop);
    // The operator raises the limit: the robot is inside it again.
    rig.speed_limit(1.0);
    assert_eq!(rig.run(520).command, Command::Heartbeat);

    let mut rig = Rig::with_config(RobotKind::Titan, "[rules.limit]\nenabled = false\n");
    rig.speed_limit(0.3);
    rig.state.motion.linear_mps = 1.0;
    assert_eq!(rig.run(3000).command, Command::Heartbeat);
    assert_eq!(
        rig.engine.enabled_rules() & SafetyRule::bit(SafetyRule::LIMIT),
        0
    );
    assert!(
        RawConfig::parse("[rules.limit]\nmargin_mps = -0.1\n")
            .unwrap()
            .validate()
            .is_err()
    );
}
