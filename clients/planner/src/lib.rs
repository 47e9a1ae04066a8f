//! `chassis-planner`: drives a robot served by `chassisd` along a path to its end and stops
//! there — a waypoint file or a built-in shape, followed with pure pursuit on the odometry pose
//! within the robot's kinematics as chassisd describes them.
//!
//! The algorithms are plain structs without a clock, tested on simulated robots stepped by hand:
//!
//! * [`path`]: polylines by arc length, windowed projection, corner rounding;
//! * [`shapes`]: `line`, `square`, `figure-eight`, sized for the robot's turning radius;
//! * [`waypoints`]: CSV and TOML waypoint files, errors by line;
//! * [`kinematics`]: what the robot can do, from the description chassisd publishes (its
//!   kinematics, turning radius and effective limits), never from a table of robots;
//! * [`tracker`]: pure pursuit, the speed profile, turns on the spot, the stop at the goal;
//! * [`watch`]: faults, staleness and holds (preemption) with their timeouts.
//!
//! [`run`] is the 50 Hz loop around them (the only module that reads the clock) and [`report`]
//! what it prints.

pub mod geometry;
pub mod kinematics;
pub mod path;
pub mod report;
pub mod run;
pub mod shapes;
pub mod tracker;
pub mod watch;
pub mod waypoints;
