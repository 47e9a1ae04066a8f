//! `chassis decode`: frames from arguments or stdin → one JSON object per decoded frame.

use std::io::{BufRead, Write};

use chassis_protocols::{CandumpLine, Profile};

use chassis_protocols::frame_json::{BoxedCodec, FrameJson};

/// What a decode run saw.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Summary {
    pub decoded: usize,
    pub failed: usize,
}

/// Decodes `args` (or, when there are none, every line of `input`) and writes JSON lines to
/// `out` and one reason per failed frame to `err`. Decoding goes on after a failure.
pub fn run(
    profile: Profile,
    args: &[String],
    input: impl BufRead,
    out: &mut impl Write,
    err: &mut impl Write,
) -> std::io::Result<Summary> {
    let mut codec = profile.codec();
    let mut summary = Summary::default();
    let mut hex = HexStream::default();
    let mut handle = |text: &str, out: &mut dyn Write, err: &mut dyn Write| {
        if codec.robot().is_can() {
            decode_can_line(&codec, text, out, err, &mut summary)
        } else {
            decode_serial_text(&mut codec, &mut hex, text, out, err, &mut summary)
        }
    };
    if args.is_empty() {
        for line in input.lines() {
            handle(&line?, out, err)?;
        }
    } else {
        for arg in args {
            handle(arg, out, err)?;
        }
    }
    if !codec.robot().is_can() {
        if hex.pending_nibble.is_some() {
            writeln!(err, "serial input ends with half a byte")?;
            summary.failed += 1;
        }
        let discarded = codec.serial_bytes_discarded();
        if discarded > 0 {
            writeln!(err, "{discarded} bytes discarded while looking for AA 55")?;
            summary.failed += 1;
        }
    }
    Ok(summary)
}

fn decode_can_line(
    codec: &BoxedCodec,
    text: &str,
    out: &mut dyn Write,
    err: &mut dyn Write,
    summary: &mut Summary,
) -> std::io::Result<()> {
    let text = text.trim();
    if text.is_empty() || text.starts_with('#') {
        return Ok(());
    }
    let result = match CandumpLine::parse(text) {
        Ok(line) => codec
            .decode_can(&line.frame)
            .map_err(|e| format!("{}: {e}", line.frame.to_candump())),
        Err(e) => Err(format!("{text}: {e}")),
    };
    emit(result, out, err, summary)
}

/// Writes a decoded frame to `out`, or why a frame did not decode to `err`, and counts it.
fn emit(
    result: Result<FrameJson, String>,
    out: &mut dyn Write,
    err: &mut dyn Write,
    summary: &mut Summary,
) -> std::io::Result<()> {
    match result {
        Ok(json) => {
            summary.decoded += 1;
            writeln!(out, "{}", serde_json::Value::Object(json))
        }
        Err(reason) => {
            summary.failed += 1;
            writeln!(err, "{reason}")
        }
    }
}

fn decode_serial_text(
    codec: &mut BoxedCodec,
    hex: &mut HexStream,
    text: &str,
    out: &mut dyn Write,
    err: &mut dyn Write,
    summary: &mut Summary,
) -> std::io::Result<()> {
    match hex.push(text) {
        Ok(bytes) => codec
            .push_serial(&bytes)
            .into_iter()
            .try_for_each(|item| emit(item.map_err(|e| e.to_string()), out, err, summary)),
        Err(reason) => emit(Err(reason.to_string()), out, err, summary),
    }
}

/// Hex text in any chunking (`AA 55 02`, `AA5502`, `aa55` + `02`) → bytes. `0x` prefixes, spaces,
/// commas and colons are ignored; a byte may even be split across chunks.
#[derive(Debug, Default)]
pub struct HexStream {
    pending_nibble: Option<u8>,
}

/// A character in hex text that is neither a hex digit nor an accepted separator.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{text}': '{digit}' is not a hex digit")]
pub struct NotHex {
    /// The chunk it was found in, trimmed.
    pub text: String,
    pub digit: char,
}

impl HexStream {
    pub fn push(&mut self, text: &str) -> Result<Vec<u8>, NotHex> {
        let cleaned = text.replace("0x", "").replace("0X", "");
        let mut bytes = Vec::with_capacity(cleaned.len() / 2);
        for c in cleaned.chars() {
            if c.is_whitespace() || c == ',' || c == ':' {
                continue;
            }
            let Some(nibble) = c.to_digit(16) else {
                return Err(NotHex {
                    text: text.trim().into(),
                    digit: c,
                });
            };
            // to_digit(16) < 16 fits a u8.
            let nibble = nibble as u8;
            match self.pending_nibble.take() {
                Some(high) => bytes.push(high << 4 | nibble),
                None => self.pending_nibble = Some(nibble),
            }
        }
        Ok(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::RobotKind;

    fn decode(
        robot: RobotKind,
        args: &[&str],
        stdin: &str,
    ) -> (Vec<serde_json::Value>, String, Summary) {
        let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        let mut out = Vec::new();
        let mut err = Vec::new();
        let summary = run(
            robot.entry().defaults(),
            &args,
            stdin.as_bytes(),
            &mut out,
            &mut err,
        )
        .unwrap();
        let json = String::from_utf8(out)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        (json, String::from_utf8(err).unwrap(), summary)
    }

    /// The JSON lines of `frames` (command-line arguments), which decode without a complaint.
    #[track_caller]
    fn decoded(robot: RobotKind, frames: &[&str]) -> Vec<serde_json::Value> {
        let (json, err, _) = decode(robot, frames, "");
        assert_eq!(err, "");
        json
    }

    #[test]
    fn titan_faults_are_named_beside_the_raw_word() {
        // The manual's layout: b5 bit5 bumper, b6 bit1 heartbeat lost, b7 bit0 under-voltage.
        let json = decoded(RobotKind::Titan, &["211#0201019000200201"]);
        assert_eq!(json[0]["vendor_fault_word"], 0x0020_0201);
        assert_eq!(
            json[0]["faults"],
            serde_json::json!([
                "heartbeat_lost",
                "battery_under_voltage",
                "bumper",
                "body_exception"
            ])
        );
        assert_eq!(json[0]["warnings"], serde_json::json!([]));
        // b7 bit2: RC link lost only warns (the chassis still drives).
        let (json, _, _) = decode(RobotKind::Titan, &["211#0001019000000004"], "");
        assert_eq!(json[0]["faults"], serde_json::json!([]));
        assert_eq!(json[0]["warnings"], serde_json::json!(["rc_link_lost"]));
    }

    #[test]
    fn titan_motor_driver_status_and_bms_alarms_are_named() {
        // 0x261 b5 = 0x41: supply under-voltage, enabled.
        let json = decoded(RobotKind::Titan, &["261#01E0001E1E410000"]);
        assert_eq!(
            json[0]["driver_status_flags"],
            serde_json::json!(["supply_under_voltage", "enabled"])
        );
        assert_bms_alarms_are_named(RobotKind::Titan);
    }

    /// 0x362: alarm 1 under-voltage, alarm 2 charge over-current, warning 1 over-temperature.
    fn assert_bms_alarms_are_named(robot: RobotKind) {
        let json = decoded(robot, &["362#04010800"]);
        assert_eq!(
            json[0]["alarms"],
            serde_json::json!(["under_voltage", "charge_over_current"])
        );
        assert_eq!(json[0]["warnings"], serde_json::json!(["over_temperature"]));
    }

    #[test]
    fn scout_mini_faults_are_named_beside_the_raw_word() {
        // 0x151: emergency stop body state, 24.0 V, b4 bit0 (CAN command checksum error),
        // count 0, checksum 0x4D.
        let json = decoded(RobotKind::ScoutMini, &["151#010100F00100004D"]);
        assert_eq!(json[0]["vendor_fault_word"], 0x0100);
        assert_eq!(json[0]["faults"], serde_json::json!(["emergency_stop"]));
        assert_eq!(json[0]["warnings"], serde_json::json!(["command_checksum"]));
    }

    #[test]
    fn a_v2_bunkers_estop_and_fault_bits_are_named_beside_the_raw_word() {
        // TV8: BUNKER MINI 2.0 with its E-stop pressed, before any 0x421.
        let json = decoded(RobotKind::Bunker, &["211#0100010000800000"]);
        assert_eq!(json[0]["vehicle_state"], 1);
        assert_eq!(json[0]["vehicle"], "estop");
        assert_eq!(json[0]["control"], "standby");
        assert_eq!(json[0]["fault_word"], 0x0080);
        assert_eq!(json[0]["fault_bits"], serde_json::json!(["estop"]));
        assert_eq!(json[0]["faults"], serde_json::json!(["emergency_stop"]));
        // HUNTER 2.0's own table (H2X): b4 bit4 host communication lost, b5 bit6 driver
        // over-temperature; RC is mode 2 there; b6 is its brake.
        let json = decoded(RobotKind::Hunter, &["211#0002010010400100"]);
        assert_eq!(json[0]["vehicle"], "normal");
        assert_eq!(json[0]["control"], "rc");
        assert_eq!(
            json[0]["fault_bits"],
            serde_json::json!(["host_communication_lost", "driver_over_temperature"])
        );
        assert_eq!(
            json[0]["faults"],
            serde_json::json!(["heartbeat_lost", "over_temperature"])
        );
        assert_eq!(json[0]["parking_brake_engaged"], true);
    }

    #[test]
    fn v2_driver_status_and_bms_alarms_are_named() {
        // ⚠ D-7: b5 = 0x40 is "enabled" on a BUNKER, "disabled" on a HUNTER 2.0.
        let (json, _, _) = decode(RobotKind::Bunker, &["261#00F0001E1E400000"], "");
        assert_eq!(
            json[0]["driver_status_flags"],
            serde_json::json!(["enabled"])
        );
        let (json, _, _) = decode(RobotKind::Hunter, &["261#00F0001E1E400000"], "");
        assert_eq!(json[0]["driver_status_flags"], serde_json::json!([]));
        assert_eq!(json[0]["driver_enabled"], false);
        assert_bms_alarms_are_named(RobotKind::HunterSe);
    }

    #[test]
    fn titan_frames_from_arguments_become_json_with_si_fields() {
        let (json, err, summary) = decode(RobotKind::Titan, &["111#0096000000000000"], "");
        assert_eq!(err, "");
        assert_eq!(
            summary,
            Summary {
                decoded: 1,
                failed: 0
            }
        );
        assert_eq!(json[0]["robot"], "titan");
        assert_eq!(json[0]["id"], "0x111");
        assert_eq!(json[0]["frame"], "motion_command");
        assert_eq!(json[0]["direction"], "to_chassis");
        assert_eq!(json[0]["linear_mps"], 0.15);
        assert_eq!(json[0]["steer_rad"], 0.0);
    }

    #[test]
    fn candump_log_lines_from_stdin_decode_and_failures_go_on() {
        let stdin = "(1700000000.000000) can0 211#000101E000000200\n\
                     garbage\n\
                     \n\
                     (1700000000.020000) can0 43A#EE\n";
        let (json, err, summary) = decode(RobotKind::Titan, &[], stdin);
        assert_eq!(
            summary,
            Summary {
                decoded: 2,
                failed: 1
            }
        );
        assert_eq!(json[0]["battery_voltage_v"], 48.0);
        assert_eq!(json[1]["frame"], "steering_zero_ack");
        assert!(
            err.starts_with("garbage: 'garbage' is not a CAN frame"),
            "{err}"
        );
    }

    #[test]
    fn unknown_ids_are_reported_by_frame() {
        let (_, err, summary) = decode(RobotKind::Titan, &["7FF#00"], "");
        assert_eq!(summary.failed, 1);
        assert_eq!(err.trim(), "7FF#00: unknown frame id 0x7FF");
    }

    #[test]
    fn hex_stream_accepts_any_chunking() {
        let mut h = HexStream::default();
        assert_eq!(h.push("AA 55 0").unwrap(), vec![0xAA, 0x55]);
        assert_eq!(
            h.push("2 0x01,01:02").unwrap(),
            vec![0x02, 0x01, 0x01, 0x02]
        );
        assert!(h.push("zz").is_err());
    }
}
