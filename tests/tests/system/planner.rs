//! `chassis-planner` against `chassisd` on each simulated robot: it drives a square back to its
//! start and exits 0, teleop preempts it and hands back, and a preemption longer than its
//! timeout makes it give up. The safety monitor is lifted (`--no-safety-monitor`): these tests
//! are about the planner.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::{Duration, Instant};

use chassis_planner::kinematics::Kinematics;
use chassis_planner::run::FINAL_STOP_S;
use chassis_planner::shapes::corner_radius_m;
use chassis_tests::*;

const UP: Duration = Duration::from_secs(10);
/// Longest a square may take (the slowest, SCOUT MINI's, takes about 26 s).
const SQUARE_LIMIT: Duration = Duration::from_secs(40);
/// The goal must be this close (odometry), m.
const GOAL_LIMIT_M: f64 = 0.10;
/// `--preempt-timeout` of the give-up tests.
const PREEMPT_TIMEOUT: Duration = Duration::from_secs(1);

/// The square each robot drives: TITAN cannot turn tighter than 1.53 m, so its corners are
/// rounded to 1.79 m (1.15 × the 1.56 m the planner asks for at least) and its square needs at
/// least 3.59 m; 4 m is its default. The others turn on the spot and drive the 2 m square of the
/// issue.
fn square_size(robot: &str) -> &'static str {
    if robot == "titan" { "4" } else { "2" }
}

/// The radius of the corners the planner builds for the robot chassisd describes (0 for a robot
/// that turns on the spot), from the same description the planner reads.
fn corner_radius(robot: &mut Robot) -> f64 {
    let described = robot.description(UP).unwrap();
    corner_radius_m(&Kinematics::from_description(&described).unwrap())
}

/// The corners of the square of `size` m, in the frame of the robot's start pose (the planner
/// drives (0, 0) → (s, 0) → (s, s) → (0, s) → (0, 0), `chassis-planner --shape square`).
fn square_corners(size: f64) -> [(f64, f64); 3] {
    [(size, 0.0), (size, size), (0.0, size)]
}

/// How close a corner must be passed, on top of the rounding, m.
const CORNER_LIMIT_M: f64 = 0.15;

/// How far from a sharp corner the path passes, m: a corner rounded to radius r is passed at
/// r(√2 − 1).
fn corner_offset(corner_radius_m: f64) -> f64 {
    corner_radius_m * (std::f64::consts::SQRT_2 - 1.0)
}

/// The shortest path around the square, m: a rounded corner saves (2 − π/2)·r of the 2r of its
/// legs; the start is not rounded, the other three corners are.
fn square_length(corner_radius_m: f64, size: f64) -> f64 {
    4.0 * size - 3.0 * (2.0 - std::f64::consts::FRAC_PI_2) * corner_radius_m
}

/// What the simulated chassis really did, asked for as it drives (`chassis sim truth`: the
/// simulator's own pose, not what the chassis reports and the service integrates).
struct Truth {
    start: Option<(f64, f64, f64)>,
    /// The latest true position, in the start frame.
    here: Option<(f64, f64)>,
    /// Path length of the true pose, m.
    travelled_m: f64,
    /// Closest true approach to each corner, m.
    nearest: [f64; 3],
    corners: [(f64, f64); 3],
    asked: Option<Instant>,
}

impl Truth {
    /// How often the truth is asked for while the robot drives.
    const PERIOD: Duration = Duration::from_millis(50);

    fn new(size: f64) -> Self {
        Self {
            start: None,
            here: None,
            travelled_m: 0.0,
            nearest: [f64::INFINITY; 3],
            corners: square_corners(size),
            asked: None,
        }
    }

    /// Asks the simulator where the robot truly is, at most once per [`Truth::PERIOD`].
    fn sample(&mut self, robot: &mut Robot) {
        if self.asked.is_some_and(|t| t.elapsed() < Self::PERIOD) {
            return;
        }
        self.asked = Some(Instant::now());
        let truth = sim_truth(robot);
        let (x, y, yaw) = (truth.get("x_m"), truth.get("y_m"), truth.get("yaw_rad"));
        let (x0, y0, yaw0) = *self.start.get_or_insert((x, y, yaw));
        let (dx, dy) = (x - x0, y - y0);
        let (sin, cos) = yaw0.sin_cos();
        let here = (dx * cos + dy * sin, -dx * sin + dy * cos);
        if let Some(last) = self.here {
            self.travelled_m += distance(last, here);
        }
        for (k, &corner) in self.corners.iter().enumerate() {
            self.nearest[k] = self.nearest[k].min(distance(here, corner));
        }
        self.here = Some(here);
    }

    /// The true drive went around the square and came back: the same rules as
    /// [`Track::assert_went_around`], on the simulator's pose. Sampled every 50 ms, so a corner
    /// passed at speed may be seen up to 50 ms away from its closest point (≈ 3 cm at 0.6 m/s).
    fn assert_went_around(&self, robot: &str, corner_radius_m: f64, size: f64, env: &Env) {
        let length = square_length(corner_radius_m, size);
        let reach = corner_offset(corner_radius_m) + CORNER_LIMIT_M;
        let back = self.here.map_or(f64::INFINITY, |(x, y)| x.hypot(y));
        eprintln!(
            "{robot}: truly travelled {:.2} m; corners truly passed at {:.3?} m; truly ends \
             {back:.3} m from the start",
            self.travelled_m, self.nearest
        );
        assert!(
            self.travelled_m >= 0.95 * length && self.travelled_m <= 1.1 * 4.0 * size,
            "{robot}: truly travelled {:.2} m, the square is {length:.2} m\n{}",
            self.travelled_m,
            env.logs()
        );
        for k in 0..3 {
            assert!(
                self.nearest[k] <= reach,
                "{robot}: corner {:?} truly passed at {:.3} m; limit {reach:.2}",
                self.corners[k],
                self.nearest[k]
            );
        }
        assert!(
            back < GOAL_LIMIT_M + CORNER_LIMIT_M,
            "{robot}: the simulator puts the robot {back:.3} m from its start"
        );
    }
}

/// What a drive looked like, from every state sample of a [`StateStream`] (a reader that loses
/// none while it is drained often enough).
///
/// The track keeps two accounts from the samples and the tests check both: the odometry pose
/// (what the planner saw), and the test's own integration of the reported body speeds over the
/// samples' stamps (`speed_pose`, independent of the service's pose integrator and of anything the
/// planner computes). A robot that never moved has neither a travelled distance nor reached
/// corners in either. [`Truth`] checks the same against the simulator's own pose.
struct Track {
    robot: &'static str,
    /// The radius of the square's rounded corners, m (0: sharp).
    corner_radius_m: f64,
    start: Option<(f64, f64, f64)>,
    last: Option<ChassisState>,
    /// Path length of the odometry pose, m.
    odometry_m: f64,
    /// ∫ |reported speed| dt, m.
    speed_m: f64,
    /// The test's integration of the reported speeds, in the start frame: x, y, yaw.
    speed_pose: (f64, f64, f64),
    /// Closest approach to each corner: by odometry, by the test's integration, m.
    nearest_odometry: [f64; 3],
    nearest_speed: [f64; 3],
    corners: [(f64, f64); 3],
    /// Samples the stream skipped (sequence gaps).
    lost: u64,
}

impl Track {
    fn new(robot: &'static str, corner_radius_m: f64, size: f64) -> Self {
        Self {
            robot,
            corner_radius_m,
            start: None,
            last: None,
            odometry_m: 0.0,
            speed_m: 0.0,
            speed_pose: (0.0, 0.0, 0.0),
            nearest_odometry: [f64::INFINITY; 3],
            nearest_speed: [f64::INFINITY; 3],
            corners: square_corners(size),
            lost: 0,
        }
    }

    fn add(&mut self, s: &ChassisState) {
        let o = &s.odometry;
        let (x0, y0, yaw0) = *self.start.get_or_insert((o.x_m, o.y_m, o.yaw_rad));
        if let Some(last) = self.last {
            if s.seq > last.seq + 1 {
                self.lost += s.seq - last.seq - 1;
            }
            let dt = s.stamp_ns.saturating_sub(last.stamp_ns) as f64 / 1e9;
            // Midpoint rule over the reported speeds.
            let v = 0.5 * f64::from(last.motion.linear_mps + s.motion.linear_mps);
            let vy = 0.5 * f64::from(last.motion.lateral_mps + s.motion.lateral_mps);
            let w = 0.5 * f64::from(last.motion.angular_radps + s.motion.angular_radps);
            let (x, y, yaw) = self.speed_pose;
            let mid = yaw + 0.5 * w * dt;
            self.speed_pose = (
                x + (v * mid.cos() - vy * mid.sin()) * dt,
                y + (v * mid.sin() + vy * mid.cos()) * dt,
                yaw + w * dt,
            );
            self.speed_m += v.hypot(vy) * dt;
            self.odometry_m += (o.x_m - last.odometry.x_m).hypot(o.y_m - last.odometry.y_m);
        }
        // The odometry pose in the start frame.
        let (dx, dy) = (o.x_m - x0, o.y_m - y0);
        let (sin, cos) = yaw0.sin_cos();
        let here = (dx * cos + dy * sin, -dx * sin + dy * cos);
        for (k, &corner) in self.corners.iter().enumerate() {
            self.nearest_odometry[k] = self.nearest_odometry[k].min(distance(here, corner));
            let (x, y, _) = self.speed_pose;
            self.nearest_speed[k] = self.nearest_speed[k].min(distance((x, y), corner));
        }
        self.last = Some(*s);
    }

    fn drain(&mut self, stream: &StateStream) {
        stream.drain(|s| self.add(s)).unwrap();
    }

    /// Checks the drive went around the square: the distance travelled (both accounts) at least
    /// the shortest path around it and not much more, every corner passed within its rounding
    /// plus [`CORNER_LIMIT_M`] (both accounts), and the test's integration back at the start.
    fn assert_went_around(&self, size: f64, env: &Env) {
        let length = square_length(self.corner_radius_m, size);
        let reach = corner_offset(self.corner_radius_m) + CORNER_LIMIT_M;
        let (x, y, _) = self.speed_pose;
        let back = x.hypot(y);
        eprintln!(
            "{}: travelled {:.2} m by odometry, {:.2} m by the reported speeds (shortest path \
             {length:.2} m); corners passed at {:.3?} m (odometry), {:.3?} m (speeds; limit \
             {reach:.2} m); the speeds' pose ends {back:.3} m from the start; {} samples lost",
            self.robot,
            self.odometry_m,
            self.speed_m,
            self.nearest_odometry,
            self.nearest_speed,
            self.lost
        );
        // The planner may cut a corner by its tolerance and overshoot a little; 10 % covers
        // both, and a robot that stood still or stopped half-way fails.
        for (what, travelled) in [("odometry", self.odometry_m), ("speeds", self.speed_m)] {
            assert!(
                travelled >= 0.95 * length && travelled <= 1.1 * 4.0 * size,
                "{}: travelled {travelled:.2} m by {what}, the square is {length:.2} m\n{}",
                self.robot,
                env.logs()
            );
        }
        for k in 0..3 {
            assert!(
                self.nearest_odometry[k] <= reach && self.nearest_speed[k] <= reach,
                "{}: corner {:?} passed at {:.3} m (odometry), {:.3} m (speeds); limit {reach:.2}",
                self.robot,
                self.corners[k],
                self.nearest_odometry[k],
                self.nearest_speed[k]
            );
        }
        assert!(
            back < GOAL_LIMIT_M + CORNER_LIMIT_M,
            "{}: the reported speeds put the robot {back:.3} m from its start",
            self.robot
        );
    }
}

/// Reads every state sample into `track` (and, given one, the simulator's pose into `truth`)
/// until `planner` exits (at most `limit`); its exit code.
fn follow(
    env: &mut Env,
    planner: usize,
    stream: &StateStream,
    track: &mut Track,
    mut truth: Option<(&mut Robot, &mut Truth)>,
    limit: Duration,
) -> Option<i32> {
    let end = Instant::now() + limit;
    while Instant::now() < end {
        stream
            .wait(Duration::from_millis(20), |s| track.add(s))
            .unwrap();
        if let Some((robot, truth)) = truth.as_mut() {
            truth.sample(robot);
        }
        if let Ok(Some(status)) = env.proc(planner).child.try_wait() {
            track.drain(stream);
            return status.code();
        }
    }
    None
}

fn position(s: &ChassisState) -> (f64, f64) {
    (s.odometry.x_m, s.odometry.y_m)
}

fn distance(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

fn active(robot: &mut Robot) -> Option<String> {
    mux(robot).active().map(|s| s.name().to_string())
}

/// The planner's last summary line.
fn summary(log: &str) -> String {
    log.lines()
        .rev()
        .find(|l| l.starts_with("reached the goal"))
        .unwrap_or("(no summary)")
        .to_string()
}

/// Waits until the planner drives the robot at more than `speed` m/s.
fn wait_until_driving(env: &Env, robot: &mut Robot, speed: f32) {
    wait_until_driving_then(env, robot, speed, || {});
}

/// [`wait_until_driving`], calling `each` on every look.
fn wait_until_driving_then(env: &Env, robot: &mut Robot, speed: f32, mut each: impl FnMut()) {
    let driving = wait_for(Duration::from_secs(15), || {
        each();
        let s = state(robot);
        s.motion.linear_mps.abs() > speed && active(robot).as_deref() == Some("planner")
    });
    assert!(driving.is_some(), "the planner never drove\n{}", env.logs());
}

/// A test's environment (`test` names it) with `chassisd` on the simulated `robot` as
/// chassis/NAME (`tag` and the pid): the environment, NAME and a connection.
fn start(test: &str, robot: &str, tag: &str) -> (Env, String, Robot) {
    Env::serving(test, (tag, robot), &["--no-safety-monitor"], UP)
}

/// Where a square starts (the goal: it ends there too), its size, the robot's corner radius, a
/// state stream and the track of it drained so far.
fn square_start(
    robot: &mut Robot,
    robot_kind: &'static str,
) -> ((f64, f64), &'static str, f64, StateStream, Track) {
    let goal = position(&state(robot));
    let size = square_size(robot_kind);
    let corners = corner_radius(robot);
    let stream = robot.state_stream(256).unwrap();
    let mut track = Track::new(robot_kind, corners, size.parse().unwrap());
    track.drain(&stream);
    (goal, size, corners, stream, track)
}

/// Starts `chassis-planner --name N args…`.
fn spawn_planner(env: &mut Env, n: &str, args: &[&str]) -> usize {
    let mut all = vec!["--name", n];
    all.extend_from_slice(args);
    env.spawn("planner", "chassis-planner", &all)
}

fn planner_drives_the_square_back_to_its_start(robot_kind: &'static str) {
    let (mut env, n, mut robot) = start(&format!("plan-square-{robot_kind}"), robot_kind, "psq");
    let (goal, size, corners, stream, mut track) = square_start(&mut robot, robot_kind);
    let mut truth = Truth::new(size.parse().unwrap());
    truth.sample(&mut robot);
    let started = Instant::now();
    let planner = spawn_planner(&mut env, &n, &["--shape", "square", "--size", size]);
    let code = follow(
        &mut env,
        planner,
        &stream,
        &mut track,
        Some((&mut robot, &mut truth)),
        SQUARE_LIMIT,
    );
    let took = started.elapsed();
    assert_eq!(code, Some(0), "the planner did not finish\n{}", env.logs());
    let end = state(&mut robot);
    let error = distance(position(&end), goal);
    let log = env.proc(planner).log_text();
    eprintln!(
        "{robot_kind}: square of {size} m: goal error {error:.3} m (odometry) after {:.1} s; \
         planner: {}",
        took.as_secs_f64(),
        summary(&log)
    );
    assert!(
        error < GOAL_LIMIT_M,
        "{robot_kind} ended {error:.3} m from its start\n{}",
        env.logs()
    );
    assert!(end.motion.linear_mps.abs() < 0.02, "still moving: {end:?}");
    assert!(log.contains("following square of"), "no start line\n{log}");
    track.assert_went_around(size.parse().unwrap(), &env);
    truth.sample(&mut robot);
    truth.assert_went_around(robot_kind, corners, size.parse().unwrap(), &env);
}

fn teleop_preempts_the_planner_and_hands_back(robot_kind: &'static str) {
    let (mut env, n, mut robot) = start(&format!("plan-handback-{robot_kind}"), robot_kind, "pho");
    let (goal, size, _, stream, mut track) = square_start(&mut robot, robot_kind);
    let started = Instant::now();
    let planner = spawn_planner(
        &mut env,
        &n,
        &[
            "--shape",
            "square",
            "--size",
            size,
            "--preempt-timeout",
            "10",
        ],
    );
    wait_until_driving_then(&env, &mut robot, 0.3, || track.drain(&stream));

    // Teleop sends a stop for one second: it wins the mux and the robot stops.
    let mut teleop = robot.source("teleop").unwrap();
    let preempted = Instant::now();
    let mut teleop_won = false;
    while preempted.elapsed() < Duration::from_secs(1) {
        teleop.stop().unwrap();
        teleop_won |= active(&mut robot).as_deref() == Some("teleop");
        track.drain(&stream);
        pause(Duration::from_millis(20));
    }
    assert!(teleop_won, "teleop never won the mux\n{}", env.logs());
    let held = state(&mut robot);
    assert!(
        held.motion.linear_mps.abs() < 0.1,
        "still at {} m/s after a second of teleop stops\n{}",
        held.motion.linear_mps,
        env.logs()
    );
    assert!(env.proc(planner).is_running(), "{}", env.logs());

    // Teleop goes quiet: after its 300 ms timeout the planner drives again.
    let handed_back = wait_for(Duration::from_secs(2), || {
        track.drain(&stream);
        active(&mut robot).as_deref() == Some("planner")
    });
    assert!(handed_back.is_some(), "not handed back\n{}", env.logs());
    let resumed = wait_for(Duration::from_secs(5), || {
        track.drain(&stream);
        state(&mut robot).motion.linear_mps.abs() > 0.1
    });
    assert!(
        resumed.is_some(),
        "the planner did not resume\n{}",
        env.logs()
    );

    let code = follow(&mut env, planner, &stream, &mut track, None, SQUARE_LIMIT);
    let took = started.elapsed();
    assert_eq!(code, Some(0), "the planner did not finish\n{}", env.logs());
    let error = distance(position(&state(&mut robot)), goal);
    let log = env.proc(planner).log_text();
    eprintln!(
        "{robot_kind}: square with a 1 s teleop stop: goal error {error:.3} m after {:.1} s; \
         planner: {}",
        took.as_secs_f64(),
        summary(&log)
    );
    assert!(error < GOAL_LIMIT_M, "{error:.3} m\n{}", env.logs());
    assert!(log.contains("preempted by teleop"), "{log}");
    assert!(log.contains("resumed after"), "{log}");
    track.assert_went_around(size.parse().unwrap(), &env);
}

fn a_preemption_longer_than_the_timeout_makes_the_planner_give_up(robot_kind: &str) {
    let (mut env, n, mut robot) = start(&format!("plan-timeout-{robot_kind}"), robot_kind, "pto");
    let planner = spawn_planner(
        &mut env,
        &n,
        &[
            "--shape",
            "line",
            "--size",
            "4",
            "--preempt-timeout",
            &PREEMPT_TIMEOUT.as_secs().to_string(),
        ],
    );
    wait_until_driving(&env, &mut robot, 0.2);
    let mut teleop = robot.source("teleop").unwrap();
    let preempted = Instant::now();
    let mut code = None;
    while preempted.elapsed() < Duration::from_secs(5) {
        teleop.stop().unwrap();
        if let Ok(Some(status)) = env.proc(planner).child.try_wait() {
            code = Some(status.code());
            break;
        }
        pause(Duration::from_millis(20));
    }
    let gave_up = preempted.elapsed();
    let log = env.proc(planner).log_text();
    eprintln!(
        "{robot_kind}: preempted with --preempt-timeout 1: the planner exited {code:?} after \
         {:.3} s",
        gave_up.as_secs_f64()
    );
    assert_eq!(code, Some(Some(1)), "{}", env.logs());
    // The rule: the planner gives up once it has been held for its preemption timeout, then
    // sends stops for FINAL_STOP_S and exits. It cannot be held before teleop's first stop, so
    // never sooner than that from `preempted`. The margin is five 20 ms periods, one for each
    // step that waits for a period (the mux status that shows teleop's win, the planner's look
    // at it, its once-a-period check of the hold, the end of its final stop on its own period
    // grid, this loop's poll of the process), and 60 ms for the process to end (a debug build
    // tearing down its iceoryx2 node). Measured on a 2-core machine shared with other builds,
    // the whole planner suite running: 32-93 ms past the rule in 24 runs.
    let rule = PREEMPT_TIMEOUT + Duration::from_secs_f64(FINAL_STOP_S);
    let margin = 5 * TICK + Duration::from_millis(60);
    assert!(
        gave_up >= rule && gave_up <= rule + margin,
        "gave up after {gave_up:?} (rule {rule:?} + {margin:?})\n{log}"
    );
    assert!(
        log.contains("chassis-planner: preempted by teleop for")
            && log.contains("longer than the preemption timeout (1 s)"),
        "{log}"
    );
    assert_eq!(active(&mut robot).as_deref(), Some("teleop"));
}

#[test]
fn an_xbot_without_its_wheel_separation_has_no_pose_and_the_planner_says_so() {
    // Over a real serial link (a pty to `chassisd sim`) the service does not know the wheel
    // separation of the simulated board, so it publishes no pose.
    let mut env = Env::new("plan-nopose");
    let n = name("pnp");
    let link = env.dir.join("xbot");
    let (_, mut robot) = env.over_pty(("xbot", &n), Line::Serial, &link, &[], UP);
    assert!(!state(&mut robot).is_valid(Group::Pose));
    let planner = spawn_planner(&mut env, &n, &["--shape", "line"]);
    let code = env.proc(planner).wait_exit(Duration::from_secs(10));
    let log = env.proc(planner).log_text();
    assert_eq!(code, Some(1), "{}", env.logs());
    // What to do comes from the description: it gives no track, and the parameters are listed
    // by `--print-config`.
    assert!(
        log.contains("publishes no pose")
            && log.contains("gives no track")
            && log.contains("chassisd --robot xbot --print-config"),
        "{log}"
    );
    assert!(state(&mut robot).motion.linear_mps.abs() < 0.01);
}

/// chassisd's `[profile] max_linear_mps = 0.4` reaches the planner through the robot's
/// description: with its default cruise speed of 0.8 m/s it drives a line asking for 0.4 m/s at
/// most — every mux decision while it drives shows what it asked — and the driver never has to
/// clamp a request of it.
#[test]
fn a_configured_speed_limit_reaches_the_planner_which_never_asks_above_it() {
    const LIMIT_MPS: f64 = 0.4;
    let mut env = Env::new("plan-limit");
    let n = name("plim");
    let config = env.write(
        "limit.toml",
        &format!("[profile]\nmax_linear_mps = {LIMIT_MPS}\n"),
    );
    env.serve("titan", &n, &["--no-safety-monitor", "--config", &config]);
    let mut robot = env.robot(&n, UP);
    let described = robot.description(UP).unwrap();
    assert_eq!(described.effective_limits().forward_mps, LIMIT_MPS);
    let planner = spawn_planner(&mut env, &n, &["--shape", "line", "--size", "3", "--json"]);
    let end = Instant::now() + SQUARE_LIMIT;
    let mut asked = Vec::new();
    let mut clamped = 0u32;
    let mut fastest = 0.0f64;
    let code = loop {
        if let Some(s) = robot.wait_state(Duration::from_millis(20)).unwrap() {
            fastest = fastest.max(f64::from(s.motion.linear_mps));
        }
        robot
            .poll_mux(|m| {
                if m.active().map(|a| a.name()) == Some("planner") {
                    asked.push(f64::from(m.requested.linear_x_mps));
                    if m.clamp_flags & ClampFlags::LINEAR_LIMIT != 0 {
                        clamped += 1;
                    }
                }
            })
            .unwrap();
        if let Ok(Some(status)) = env.proc(planner).child.try_wait() {
            break status.code();
        }
        assert!(
            Instant::now() < end,
            "the planner did not finish\n{}",
            env.logs()
        );
    };
    let log = env.proc(planner).log_text();
    let most = asked.iter().copied().fold(0.0f64, f64::max);
    eprintln!(
        "titan with max_linear_mps = {LIMIT_MPS}: {} decisions for the planner, it asked for at \
         most {most:.3} m/s, the robot drove at most {fastest:.3} m/s; {clamped} clamped",
        asked.len()
    );
    assert_eq!(code, Some(0), "{}", env.logs());
    assert!(
        asked.len() > 50,
        "{} decisions\n{}",
        asked.len(),
        env.logs()
    );
    // The request is an f32 on the wire.
    assert!(most <= LIMIT_MPS + 1e-6, "asked for {most} m/s\n{log}");
    assert!(
        most > 0.9 * LIMIT_MPS,
        "it never drove at its limit: {most} m/s\n{log}"
    );
    assert_eq!(
        clamped, 0,
        "the driver clamped the planner's requests\n{log}"
    );
    assert!(
        fastest <= LIMIT_MPS + 0.02,
        "the robot drove at {fastest} m/s"
    );
    // The planner says which limits it follows, and where from.
    let start = log
        .lines()
        .find(|l| l.contains("\"event\":\"start\""))
        .unwrap_or_else(|| panic!("no start line\n{log}"));
    let start: serde_json::Value = serde_json::from_str(start).unwrap();
    assert_eq!(start["limits"]["max_linear_mps"], 0.4, "{start}");
    assert_eq!(start["speed_mps"], 0.4, "{start}");
    assert_eq!(start["described_as"], "AgileX TITAN (titan)", "{start}");
}

#[test]
fn titan_drives_a_square_with_rounded_corners_back_to_its_start() {
    planner_drives_the_square_back_to_its_start("titan");
}

#[test]
fn scout_mini_drives_a_square_back_to_its_start_turning_on_the_spot() {
    planner_drives_the_square_back_to_its_start("scout-mini");
}

#[test]
fn xbot_drives_a_square_back_to_its_start_turning_on_the_spot() {
    planner_drives_the_square_back_to_its_start("xbot");
}

#[test]
fn teleop_preempts_the_titan_planner_and_hands_back() {
    teleop_preempts_the_planner_and_hands_back("titan");
}

#[test]
fn teleop_preempts_the_scout_mini_planner_and_hands_back() {
    teleop_preempts_the_planner_and_hands_back("scout-mini");
}

#[test]
fn teleop_preempts_the_xbot_planner_and_hands_back() {
    teleop_preempts_the_planner_and_hands_back("xbot");
}

#[test]
fn a_titan_planner_preempted_longer_than_its_timeout_exits_non_zero() {
    a_preemption_longer_than_the_timeout_makes_the_planner_give_up("titan");
}

#[test]
fn a_scout_mini_planner_preempted_longer_than_its_timeout_exits_non_zero() {
    a_preemption_longer_than_the_timeout_makes_the_planner_give_up("scout-mini");
}

#[test]
fn an_xbot_planner_preempted_longer_than_its_timeout_exits_non_zero() {
    a_preemption_longer_than_the_timeout_makes_the_planner_give_up("xbot");
}
