//! Drive a robot for two seconds as the `teleop` source and print what it reports.
//!
//! ```sh
//! chassisd --robot titan --no-safety-monitor &
//! cargo run -p chassis-client --example drive -- titan
//! ```

use std::time::Duration;

use chassis_client::{ClientError, ControlMode, Robot, Ticker, VelocityRequest, now_ns};

fn main() -> Result<(), ClientError> {
    let name = std::env::args().nth(1).unwrap_or_else(|| "titan".into());
    let mut robot = Robot::connect(&name)?;
    let mut teleop = robot.source("teleop")?;
    let mut ticker = Ticker::new(Duration::from_millis(50));
    let start = now_ns();
    while now_ns() - start < 2_000_000_000 {
        teleop.send(VelocityRequest::twist(0.4, 0.2))?;
        if let Some(state) = robot.latest_state()? {
            println!(
                "{:6.3} m/s {:6.3} rad/s  pose ({:5.2}, {:5.2})  {}",
                state.motion.linear_mps,
                state.motion.angular_radps,
                state.odometry.x_m,
                state.odometry.y_m,
                ControlMode::name(state.system.control_mode)
            );
        }
        ticker.wait();
    }
    teleop.stop()?;
    if let Some(mux) = robot.latest_mux()? {
        println!(
            "mux: active {:?}",
            mux.active().map(|s| s.name().to_string())
        );
    }
    Ok(())
}
