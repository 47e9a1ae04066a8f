//! `chassis encode`: the frames the service would send for a command.

use chassis_protocols::{
    Command, CommandError, Planned, Profile, agilex_v2, scout_mini, titan, xbot,
};

/// The frames for `command`, one per line: CAN as candump `ID#HEX`, XBot as spaced hex. SCOUT MINI
/// counters start at 0. Also returns what was clamped on the way (`ClampFlags`).
pub fn encode(profile: &Profile, command: &Command) -> Result<(Vec<String>, u32), CommandError> {
    match profile {
        Profile::Titan(p) => lines(titan::frames_for(command, p)?, |f, _| {
            f.encode(p).map(|c| c.to_candump())
        }),
        Profile::ScoutMini(p) => lines(scout_mini::frames_for(command, p)?, |f, count| {
            f.encode(count, p).map(|c| c.to_candump())
        }),
        Profile::V2(p) => lines(agilex_v2::frames_for(command, p)?, |f, _| {
            f.encode(p).map(|c| c.to_candump())
        }),
        Profile::Xbot(p) => lines(xbot::frames_for(command, p)?, |f, _| {
            f.encode(p).map(|bytes| spaced_hex(&bytes))
        }),
    }
}

/// The planned frames one per line, by `line(frame, count)` (`count` from 0: the SCOUT MINI's
/// counter; a plan is a few frames), and what was clamped. Stops at the first frame that does
/// not encode.
fn lines<F, E>(
    planned: Planned<F>,
    line: impl Fn(&F, u8) -> Result<String, E>,
) -> Result<(Vec<String>, u32), CommandError>
where
    CommandError: From<E>,
{
    let lines = planned
        .frames
        .iter()
        .zip(0u8..)
        .map(|(f, count)| line(f, count))
        .collect::<Result<_, _>>()?;
    Ok((lines, planned.clamp_flags))
}

/// `AA 55 02 01 01 02`.
pub fn spaced_hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::{RobotKind, Turn};

    /// `chassis encode --robot KIND velocity --vx 0.3 --wz 0`.
    fn forward(kind: RobotKind) -> Vec<String> {
        let profile = Profile::from_table(kind, None, &toml::Table::new()).unwrap();
        let command = Command::Velocity {
            linear_x_mps: 0.3,
            linear_y_mps: 0.0,
            turn: Turn::YawRate(0.0),
        };
        let (lines, clamp_flags) = encode(&profile, &command).unwrap();
        assert_eq!(clamp_flags, 0);
        lines
    }

    #[test]
    fn a_forward_command_becomes_each_robots_motion_frame() {
        assert_eq!(forward(RobotKind::Titan), ["111#012C000000000000"]);
        // SCOUT MINI (v1): the frame counter (b6) starts at 0.
        assert_eq!(forward(RobotKind::ScoutMini), ["130#0100060000000040"]);
        assert_eq!(
            forward(RobotKind::Xbot),
            ["AA 55 0D 03 9A 99 99 3E 00 00 00 00 00 00 00 00 AA"]
        );
    }
}
