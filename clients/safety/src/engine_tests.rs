//! The rule engine on simulated time.

use super::*;
use crate::config::RawConfig;
use chassis_client::RobotKind;

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

impl Rig {
    fn with_config(robot: u8, toml: &str) -> Self {
        let config = RawConfig::parse(toml).unwrap().validate().unwrap();
        let mut state = ChassisState {
            robot,
            ..ChassisState::default()
        };
        state.system.battery_soc_pct = 80.0;
        state.system.battery_voltage_v = match robot {
            RobotKind::TITAN => 50.0,
            RobotKind::XBOT => 25.5,
            _ => 27.0,
        };
        state.ranges.ultrasonic_m = [6.0; 3];
        state.ranges.ir_m = [0.8; 3];
        let mut rig = Self {
            engine: Engine::new(config, "safety"),
            state,
            mux: Some(mux_with_estop()),
            now_ms: 0,
            frozen: false,
        };
        rig.refresh();
        rig
    }

    fn new(robot: u8) -> Self {
        Self::with_config(robot, "")
    }

    fn refresh(&mut self) {
        let now = ns(self.now_ms);
        self.state.seq += 1;
        self.state.stamp_ns = now;
        for group in [Group::Motion, Group::System] {
            self.state.touch(group, now);
        }
        match self.state.robot {
            RobotKind::TITAN => self.state.touch(Group::BmsPack, now),
            RobotKind::XBOT => self.state.touch(Group::Ranges, now),
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
    for robot in [RobotKind::TITAN, RobotKind::SCOUT_MINI, RobotKind::XBOT] {
        let mut rig = Rig::new(robot);
        let d = rig.run(2000);
        assert_eq!(d.command, Command::Heartbeat, "{}", RobotKind::name(robot));
        assert_eq!(d.action, SafetyAction::NONE);
        assert_eq!(d.active_rules, 0);
        assert!(d.events.is_empty(), "{:?}", texts(&d));
        assert_eq!(d.estop, EstopState::FREE);
    }
}

#[test]
fn a_non_warning_fault_stops_at_once_and_releases_after_its_release_time() {
    let mut rig = Rig::new(RobotKind::TITAN);
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
    let mut rig = Rig::new(RobotKind::TITAN);
    rig.state.system.fault_flags = FaultFlags::WARNINGS;
    let d = rig.run(1000);
    assert_eq!(d.command, Command::Heartbeat);
    assert!(d.events.is_empty(), "{:?}", texts(&d));
}

#[test]
fn the_battery_triggers_below_its_threshold_after_the_trigger_time_and_releases_above_the_margin() {
    let mut rig = Rig::new(RobotKind::TITAN);
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
    let mut rig = Rig::new(RobotKind::XBOT);
    for _ in 0..5 {
        rig.state.system.battery_voltage_v = 23.0; // sag while accelerating
        assert_eq!(rig.run(600).command, Command::Heartbeat);
        rig.state.system.battery_voltage_v = 25.0;
        rig.run(100);
    }
}

#[test]
fn a_robot_without_a_bms_is_judged_by_its_own_voltage_threshold() {
    let mut rig = Rig::new(RobotKind::XBOT);
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
    let mut rig = Rig::new(RobotKind::TITAN);
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
    let mut rig = Rig::new(RobotKind::TITAN);
    rig.run(200);
    rig.state.link_flags = LinkFlags::BUS_DOWN;
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["stale: bus_down"]);
    rig.state.link_flags = 0;
    assert_eq!(rig.run(600).command, Command::Heartbeat);

    // Samples keep coming (the service refreshes them), but no frame from the chassis: its
    // stamp stops moving.
    let mut rig = Rig::new(RobotKind::XBOT);
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
    let mut rig = Rig::new(RobotKind::TITAN);
    rig.state = ChassisState::default();
    rig.frozen = true;
    let d = rig.run(20);
    assert_eq!(d.command, Command::Stop);
}

#[test]
fn an_obstacle_ahead_in_the_slow_zone_limits_only_the_forward_speed() {
    let mut rig = Rig::new(RobotKind::XBOT);
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
    let mut rig = Rig::new(RobotKind::XBOT);
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
    assert!(r.is_limit() && r.is_finite());
    assert_eq!(0.3f32.clamp(-r.limit_reverse_mps, r.limit_forward_mps), 0.0);
    assert_eq!(
        (-0.2f32).clamp(-r.limit_reverse_mps, r.limit_forward_mps),
        -0.2
    );
}

#[test]
fn an_obstacle_behind_blocks_reversing_but_not_driving_forward() {
    let mut rig = Rig::new(RobotKind::XBOT);
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
    let mut rig = Rig::new(RobotKind::XBOT);
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
    let mut rig = Rig::new(RobotKind::XBOT);
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
    let mut rig = Rig::new(RobotKind::XBOT);
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
    for robot in [RobotKind::TITAN, RobotKind::SCOUT_MINI] {
        let mut rig = Rig::new(robot);
        // Zeros in fields the robot never reported are not readings.
        rig.state.ranges = Default::default();
        let d = rig.run(1000);
        assert_eq!(d.command, Command::Heartbeat);
    }
}

#[test]
fn ranges_that_stop_updating_count_as_obstacles_in_both_directions() {
    let mut rig = Rig::new(RobotKind::XBOT);
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
    let mut rig = Rig::new(RobotKind::XBOT);
    rig.state.ranges.ultrasonic_m = [6.0, f32::NAN, 6.0];
    let d = rig.run(40);
    assert!(matches!(d.command, Command::Limit(e) if e.forward_mps == 0.0));
}

#[test]
fn a_speed_above_the_limit_stops_and_releases_below_the_margin() {
    let mut rig = Rig::new(RobotKind::XBOT);
    rig.state.motion.linear_mps = -1.7;
    assert_eq!(
        rig.run(180).command,
        Command::Heartbeat,
        "200 ms trigger time"
    );
    let d = rig.run(40);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(texts(&d), ["speed: 1.70 m/s > 1.65 m/s"]);
    rig.state.motion.linear_mps = 1.5;
    assert_eq!(rig.run(2000).command, Command::Stop, "inside the margin");
    rig.state.motion.linear_mps = 1.4;
    let d = rig.run(520);
    assert_eq!(d.command, Command::Heartbeat);
    assert_eq!(texts(&d), ["speed: 1.40 m/s < 1.45 m/s, released"]);
}

#[test]
fn the_bumper_latches_the_estop_until_the_operator_releases_it() {
    let mut rig = Rig::new(RobotKind::TITAN);
    rig.run(100);
    rig.state.system.fault_flags = FaultFlags::BUMPER | FaultFlags::BODY_EXCEPTION;
    let d = rig.run(20);
    assert_eq!(d.command, Command::StopAndLock(1));
    assert_eq!(d.action, SafetyAction::LATCH);
    // The TITAN reports a body exception with any fault bit: the fault rule stops as well.
    assert_eq!(texts(&d), ["fault: body_exception", "bumper: pressed"]);
    // Until the mux shows the lock held, every request engages it.
    assert_eq!(rig.run(60).command, Command::StopAndLock(1));
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
    assert_eq!(rig.run(20).command, Command::StopAndLock(1));
}

#[test]
fn a_release_while_the_bumper_is_still_pressed_does_not_relatch_until_it_is_pressed_again() {
    let mut rig = Rig::new(RobotKind::TITAN);
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
    assert_eq!(rig.run(20).command, Command::StopAndLock(1));
}

#[test]
fn a_latch_without_a_mux_status_stops_until_the_lock_can_be_engaged() {
    let mut rig = Rig::new(RobotKind::TITAN);
    rig.mux = None;
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    let d = rig.run(40);
    assert_eq!(d.command, Command::Stop);
    assert_eq!(d.action, SafetyAction::LATCH);
    assert_eq!(d.estop, EstopState::UNKNOWN);
    rig.mux = Some(mux_with_estop());
    assert_eq!(rig.run(20).command, Command::StopAndLock(1));
}

#[test]
fn a_restarted_service_gets_the_latched_lock_engaged_again() {
    let mut rig = Rig::new(RobotKind::TITAN);
    rig.state.system.fault_flags = FaultFlags::BUMPER;
    rig.run(40);
    rig.lock(Some(0));
    assert_eq!(rig.run(100).command, Command::Stop);
    // A new chassisd: its mux starts again at seq 1 with every lock free.
    rig.mux = Some(mux_with_estop());
    let d = rig.run(20);
    assert_eq!(d.command, Command::StopAndLock(1));
    assert_eq!(d.notices.len(), 1, "{:?}", d.notices);
}

#[test]
fn without_an_estop_lock_a_latching_rule_acts_as_a_stop() {
    let mut rig = Rig::new(RobotKind::TITAN);
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
    let mut rig = Rig::new(RobotKind::XBOT);
    rig.run(100);
    assert!(rig.engine.request_operator_estop());
    let d = rig.run(20);
    assert_eq!(d.command, Command::StopAndLock(1));
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
    let mut rig = Rig::new(RobotKind::XBOT);
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
    let mut rig = Rig::with_config(RobotKind::TITAN, "[rules.battery]\naction = \"slow\"\n");
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
    let mut rig = Rig::with_config(RobotKind::XBOT, "[rules.ultrasonic]\naction = \"stop\"\n");
    rig.state.ranges.ultrasonic_m = [0.5; 3];
    assert!(matches!(rig.run(40).command, Command::Limit(_)));
    rig.state.ranges.ultrasonic_m = [0.2; 3];
    assert_eq!(rig.run(20).command, Command::Stop);
}

#[test]
fn disabled_rules_never_trigger() {
    let mut rig = Rig::with_config(
        RobotKind::XBOT,
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
    let mut rig = Rig::new(RobotKind::XBOT);
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
