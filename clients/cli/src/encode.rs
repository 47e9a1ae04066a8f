//! `chassis encode`: the frames the service would send for a command.

use chassis_protocols::{Command, CommandError, Profile, agilex_v2, scout_mini, titan, xbot};

/// The frames for `command`, one per line: CAN as candump `ID#HEX`, XBot as spaced hex. SCOUT MINI
/// counters start at 0. Also returns what was clamped on the way (`ClampFlags`).
pub fn encode(profile: &Profile, command: &Command) -> Result<(Vec<String>, u32), CommandError> {
    match profile {
        Profile::Titan(p) => {
            let planned = titan::frames_for(command, p)?;
            let lines = planned
                .frames
                .iter()
                .map(|f| f.encode(p).map(|c| c.to_candump()))
                .collect::<Result<_, _>>()?;
            Ok((lines, planned.clamp_flags))
        }
        Profile::ScoutMini(p) => {
            let planned = scout_mini::frames_for(command, p)?;
            let lines = planned
                .frames
                .iter()
                .zip(0u8..)
                .map(|(f, count)| f.encode(count, p).map(|c| c.to_candump()))
                .collect::<Result<_, _>>()?;
            Ok((lines, planned.clamp_flags))
        }
        Profile::V2(p) => {
            let planned = agilex_v2::frames_for(command, p)?;
            let lines = planned
                .frames
                .iter()
                .map(|f| f.encode(p).map(|c| c.to_candump()))
                .collect::<Result<_, _>>()?;
            Ok((lines, planned.clamp_flags))
        }
        Profile::Xbot(p) => {
            let planned = xbot::frames_for(command, p)?;
            let lines = planned
                .frames
                .iter()
                .map(|f| f.encode(p).map(|bytes| spaced_hex(&bytes)))
                .collect::<Result<_, _>>()?;
            Ok((lines, planned.clamp_flags))
        }
    }
}

/// `AA 55 02 01 01 02`.
pub fn spaced_hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}
