//! `chassis-safety`: the safety monitor of a robot served by `chassisd`.
//!
//! It is the mux's `required` source: it publishes on the `safety` source (priority 255, 200 ms
//! timeout by default) at least every 50 ms, so if it dies or hangs the robot stops within the
//! source's timeout. It runs on its own clock — rules are evaluated on every new state sample
//! and at least every 20 ms — and it watches the sensors it relies on: a state that stops
//! arriving, a silent chassis and blind range sensors all stop the robot.
//!
//! * [`config`]: the TOML file, its defaults and its validation;
//! * [`levels`]: the speed and battery levels, from the robot's description (never from a
//!   table of robots here) or the file, and where each comes from;
//! * [`engine`]: the pure rule engine (state and mux status in, a decision out);
//! * [`plausibility`]: the wheels follow the command (runaway, direction, following);
//! * [`monitor`]: the loop that connects, reads the description, decides, publishes and
//!   reconnects;
//! * [`print`](mod@print): `--print-config`, every value with where it comes from.
//!
//! What it publishes on its source, by the strictest rule in force: a heartbeat while all is
//! well; a speed envelope (`VelocityRequest::limit`) for `slow` rules and the range rules' zones
//! (only motion towards the obstacle is slowed or blocked); a zero request for `stop` rules; a
//! zero request that engages the `estop` lock for `latch` rules, which only the operator releases
//! (`chassis control estop-release`). Its decision, every rule in force and its last event are
//! published as `SafetyStatus` on `chassis/<name>/safety` and shown by `chassis status`.

pub mod config;
pub mod engine;
pub mod levels;
pub mod monitor;
pub mod plausibility;
pub mod print;
