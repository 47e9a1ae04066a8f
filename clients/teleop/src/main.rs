//! `chassis-teleop`: drive a robot served by chassisd from the keyboard, in a terminal (also
//! over SSH).
//!
//! ```sh
//! chassis-teleop --name titan            # arrows/WASD drive, +/- speed, space stop, e e-stop
//! ```
//!
//! Keys drive only while held: the command is published as the `teleop` source at 20 Hz while
//! a motion key is down, one stop follows when it comes up, and then nothing, so the mux hands
//! the robot back to lower-priority sources. How a release is told apart in terminals that
//! report none is explained in `keys.rs`.

use std::process::ExitCode;

use clap::Parser;

mod app;
mod keys;
mod view;

/// Drive a robot served by chassisd from the keyboard: arrows/WASD drive while held, +/-
/// change the speed step, space stops, `e` engages the e-stop lock, q/Esc quit.
#[derive(Debug, Parser)]
#[command(name = "chassis-teleop", version)]
struct Args {
    /// The robot's name (chassisd --name).
    #[arg(long, default_value = "titan")]
    name: String,
    /// The configured velocity source to publish as.
    #[arg(long, default_value = "teleop")]
    source: String,
    /// Forward speed per speed step, m/s.
    #[arg(long, default_value_t = 0.1)]
    linear_step: f32,
    /// Yaw rate per speed step, rad/s.
    #[arg(long, default_value_t = 0.2)]
    angular_step: f32,
    /// Largest forward speed, m/s.
    #[arg(long, default_value_t = 1.0)]
    max_linear: f32,
    /// Largest yaw rate, rad/s.
    #[arg(long, default_value_t = 1.0)]
    max_angular: f32,
    /// Where the terminal reports no key releases: how long a first press holds, ms (above
    /// the keyboard's auto-repeat delay).
    #[arg(long, default_value_t = 700)]
    first_hold_ms: u64,
    /// Where the terminal reports no key releases: how long each auto-repeat holds, ms (above
    /// the auto-repeat period; the robot stops this long after the key comes up).
    #[arg(long, default_value_t = 200)]
    repeat_hold_ms: u64,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let options = app::Options {
        name: args.name,
        source: args.source,
        settings: keys::Settings {
            linear_step_mps: args.linear_step,
            angular_step_radps: args.angular_step,
            max_linear_mps: args.max_linear,
            max_angular_radps: args.max_angular,
            first_hold_ns: args.first_hold_ms.saturating_mul(1_000_000),
            repeat_hold_ns: args.repeat_hold_ms.saturating_mul(1_000_000),
            ..keys::Settings::default()
        },
    };
    match app::run(&options) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("chassis-teleop: {err:#}");
            ExitCode::FAILURE
        }
    }
}
