//! NMEA tests: real receivers' sentences (checksums computed independently), the XBot manual's
//! example stream, no-fix sentences, bad input, the line reader and round trips.

use chassis_interfaces::GpsFix;
use proptest::prelude::*;

use super::*;
use crate::DecodeError;

mod crosscheck;

fn parse(line: &str) -> Sentence {
    parse_sentence(line).unwrap_or_else(|e| panic!("{line}: {e}"))
}

/// Parses, checks that formatting parses back to the same value, returns the sentence.
fn round_trip(line: &str) -> Sentence {
    let s = parse(line);
    let text = s.to_sentence();
    assert_eq!(parse_sentence(&text), Ok(s), "{line} → {text}");
    s
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

fn applied(lines: &[&str]) -> GpsFix {
    let mut fix = GpsFix::default();
    for line in lines {
        apply(&parse(line), &mut fix);
    }
    fix
}

// Classic examples from receiver documentation; each checksum is the published one and was
// recomputed independently.
const GGA: &str = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47";
const RMC: &str = "$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A";
const VTG: &str = "$GPVTG,054.7,T,034.4,M,005.5,N,010.2,K*48";
const GLL: &str = "$GPGLL,4916.45,N,12311.12,W,225444,A,*1D";
const ZDA: &str = "$GPZDA,201530.00,04,07,2002,00,00*60";
const GSA: &str = "$GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1*39";
const GSV: &str = "$GPGSV,2,1,08,01,40,083,46,02,17,308,41,12,07,344,39,14,22,228,45*75";
// Southern and western hemispheres, other talkers.
const RMC_SYDNEY: &str = "$GNRMC,083559.00,A,3352.12800,S,15112.55800,E,0.004,77.52,091202,,,A*56";
const GGA_BUENOS_AIRES: &str =
    "$GPGGA,154500.00,3436.4000,S,05822.8000,W,2,10,0.8,25.0,M,14.0,M,1.2,0001*71";
const GSA_NMEA_4_11: &str = "$GNGSA,A,3,80,71,73,79,69,,,,,,,,1.83,1.09,1.47,2*09";
// No fix.
const GGA_NO_FIX: &str = "$GPGGA,002153.000,,,,,0,00,,,M,,M,,*7D";
const RMC_VOID: &str = "$GPRMC,002153.000,V,,,,,,,,,,N*48";
const GSA_NO_FIX: &str = "$GPGSA,A,1,,,,,,,,,,,,,,,*1E";
// The XBot manual's example stream, but for its two GGA sentences (their printed checksums do not
// match).
const XBOT_MANUAL_STREAM: [&str; 6] = [
    "$GPRMC,121252.000,A,3958.3032,N,11629.6046,E,15.15,359.95,070306,,,A*54",
    "$GPVTG,359.95,T,,M,15.15,N,28.0,K,A*04",
    "$GPGSA,A,3,14,15,05,22,18,26,,,,,,,2.1,1.2,1.7*3D",
    "$GPGSV,3,1,10,18,84,067,23,09,67,067,27,22,49,312,28,15,47,231,30*70",
    "$GPGSV,3,2,10,21,32,199,23,14,25,272,24,05,21,140,32,26,14,070,20*7E",
    "$GPGSV,3,3,10,29,07,074,,30,07,163,28*7D",
];

#[test]
fn gga_reads_time_position_quality_and_altitude() {
    let Sentence::Gga(g) = round_trip(GGA) else {
        panic!()
    };
    assert_eq!(g.talker, Talker::GPS);
    assert_eq!(
        g.time,
        Some(UtcTime {
            hour: 12,
            minute: 35,
            second: 19.0
        })
    );
    assert!(close(g.latitude_deg.unwrap(), 48.0 + 7.038 / 60.0));
    assert!(close(g.longitude_deg.unwrap(), 11.0 + 31.0 / 60.0));
    assert_eq!((g.fix_quality, g.satellites), (Some(1), Some(8)));
    assert_eq!((g.hdop, g.altitude_m), (Some(0.9), Some(545.4)));
    assert_eq!(g.geoid_separation_m, Some(46.9));
    assert_eq!((g.dgps_age_s, g.dgps_station), (None, None));
}

#[test]
fn rmc_reads_status_speed_course_date_and_variation() {
    let Sentence::Rmc(r) = round_trip(RMC) else {
        panic!()
    };
    assert!(r.valid);
    assert_eq!((r.speed_knots, r.course_deg), (Some(22.4), Some(84.4)));
    assert_eq!(
        r.date,
        Some(UtcDate {
            year: 1994,
            month: 3,
            day: 23
        })
    );
    assert_eq!(r.magnetic_variation_deg, Some(-3.1), "W is negative");
    assert_eq!(r.mode, None, "pre-2.3 sentence without mode");
}

#[test]
fn vtg_gll_zda_gsa_and_gsv_parse() {
    let Sentence::Vtg(v) = round_trip(VTG) else {
        panic!()
    };
    assert_eq!(
        (
            v.course_true_deg,
            v.course_magnetic_deg,
            v.speed_knots,
            v.speed_kmh
        ),
        (Some(54.7), Some(34.4), Some(5.5), Some(10.2))
    );
    let Sentence::Gll(l) = round_trip(GLL) else {
        panic!()
    };
    assert!(close(l.latitude_deg.unwrap(), 49.0 + 16.45 / 60.0));
    assert!(close(l.longitude_deg.unwrap(), -(123.0 + 11.12 / 60.0)));
    assert_eq!((l.valid, l.mode), (Some(true), None));
    let Sentence::Zda(z) = round_trip(ZDA) else {
        panic!()
    };
    assert_eq!(z.date.unwrap().yyyymmdd(), 20_020_704);
    assert_eq!(
        z.time.unwrap().seconds_of_day(),
        20.0 * 3600.0 + 15.0 * 60.0 + 30.0
    );
    assert_eq!(
        (z.local_zone_hours, z.local_zone_minutes),
        (Some(0), Some(0))
    );
    let Sentence::Gsa(a) = round_trip(GSA) else {
        panic!()
    };
    assert_eq!((a.selection, a.fix_type), (Some('A'), Some(3)));
    assert_eq!(
        a.satellite_ids[..6],
        [Some(4), Some(5), None, Some(9), Some(12), None]
    );
    assert_eq!((a.pdop, a.hdop, a.vdop), (Some(2.5), Some(1.3), Some(2.1)));
    let Sentence::Gsv(s) = round_trip(GSV) else {
        panic!()
    };
    assert_eq!(
        (s.message_count, s.message_number, s.satellites_in_view),
        (2, 1, Some(8))
    );
    assert_eq!(
        s.satellites[3],
        Some(SatelliteInView {
            id: 14,
            elevation_deg: Some(22),
            azimuth_deg: Some(228),
            snr_db: Some(45)
        })
    );
}

#[test]
fn southern_and_western_hemispheres_are_negative_and_any_talker_is_accepted() {
    let Sentence::Rmc(r) = round_trip(RMC_SYDNEY) else {
        panic!()
    };
    assert_eq!(r.talker, Talker::GNSS);
    assert!(close(r.latitude_deg.unwrap(), -(33.0 + 52.128 / 60.0)));
    assert!(close(r.longitude_deg.unwrap(), 151.0 + 12.558 / 60.0));
    assert_eq!(r.mode, Some('A'));
    let Sentence::Gga(g) = round_trip(GGA_BUENOS_AIRES) else {
        panic!()
    };
    assert!(close(g.latitude_deg.unwrap(), -(34.0 + 36.4 / 60.0)));
    assert!(close(g.longitude_deg.unwrap(), -(58.0 + 22.8 / 60.0)));
    assert_eq!((g.dgps_age_s, g.dgps_station), (Some(1.2), Some(1)));
    let fix = applied(&[GGA_BUENOS_AIRES]);
    assert!(fix.latitude_deg < 0.0 && fix.longitude_deg < 0.0);
    assert_eq!(fix.fix_quality, 2);
}

#[test]
fn nmea_4_11_trailing_fields_are_accepted() {
    let Sentence::Gsa(a) = round_trip(GSA_NMEA_4_11) else {
        panic!()
    };
    assert_eq!(a.satellite_ids[4], Some(69));
    assert_eq!(a.vdop, Some(1.47));
    // GSV with a signal id after two satellites.
    let body = "GPGSV,3,3,10,29,07,074,,30,07,163,28,1";
    let line = format!("${body}*{:02X}", checksum(body));
    let Sentence::Gsv(s) = parse(&line) else {
        panic!()
    };
    assert_eq!(s.satellites[1].unwrap().id, 30);
    assert_eq!(s.satellites[2], None);
}

#[test]
fn the_xbot_manuals_stream_parses_except_two_gga_checksums_that_do_not_match() {
    for line in XBOT_MANUAL_STREAM {
        round_trip(line);
    }
    // The manual prints these GGA sentences with *77 and *72; the XOR of their characters is 75
    // and 70. Their printed checksums do match the RMC's coordinates (3958.3032 N 11629.6046 E):
    // the fields were edited after the checksums were computed.
    assert_eq!(
        parse_sentence(
            "$GPGGA,121252.000,3937.3032,N,11611.6046,E,1,05,2.0,45.9,M,-5.7,M,,0000*77"
        ),
        Err(DecodeError::BadChecksum {
            expected: 0x75,
            got: 0x77
        })
    );
    assert_eq!(
        parse_sentence(
            "$GPGGA,121253.000,3937.3090,N,11611.6057,E,1,06,1.2,44.6,M,-5.7,M,,0000*72"
        ),
        Err(DecodeError::BadChecksum {
            expected: 0x70,
            got: 0x72
        })
    );
    round_trip("$GPGGA,121252.000,3958.3032,N,11629.6046,E,1,05,2.0,45.9,M,-5.7,M,,0000*77");
    let Sentence::Gga(g) =
        round_trip("$GPGGA,121252.000,3937.3032,N,11611.6046,E,1,05,2.0,45.9,M,-5.7,M,,0000*75")
    else {
        panic!()
    };
    assert_eq!(g.dgps_station, Some(0));
    assert_eq!(g.geoid_separation_m, Some(-5.7));
    assert_eq!(g.time.unwrap().second, 52.0);
}

#[test]
fn a_fix_collects_position_time_date_speed_course_and_quality() {
    let fix = applied(&[ZDA, GGA, GSA, RMC]);
    assert!(close(fix.latitude_deg, 48.0 + 7.038 / 60.0));
    assert!(close(fix.longitude_deg, 11.0 + 31.0 / 60.0));
    assert_eq!(fix.utc_time_s, 12.0 * 3600.0 + 35.0 * 60.0 + 19.0);
    assert_eq!(fix.utc_date, 19_940_323, "RMC's date came last");
    assert_eq!((fix.fix_quality, fix.satellites, fix.fix_type), (1, 8, 3));
    assert_eq!(fix.altitude_m, 545.4);
    assert_eq!(fix.hdop, 1.3, "GSA's HDOP came after GGA's");
    assert!((f64::from(fix.speed_mps) - 22.4 * 1852.0 / 3600.0).abs() < 1e-5);
    assert!((f64::from(fix.course_rad) - 84.4f64.to_radians()).abs() < 1e-6);
    assert!(fix.has_fix());

    let fix = applied(&[VTG]);
    assert!((f64::from(fix.speed_mps) - 5.5 * 1852.0 / 3600.0).abs() < 1e-5);
    assert!((f64::from(fix.course_rad) - 54.7f64.to_radians()).abs() < 1e-6);
    let fix = applied(&[RMC_SYDNEY]);
    assert_eq!(fix.fix_quality, 1, "RMC alone implies a GPS fix");
    assert_eq!(fix.utc_date, 20_021_209);
    let fix = applied(&[GLL]);
    assert!(fix.longitude_deg < 0.0);
    assert_eq!(fix.utc_time_s, 22.0 * 3600.0 + 54.0 * 60.0 + 44.0);
}

#[test]
fn no_fix_sentences_report_quality_0_and_never_a_position_at_0_0_taken_from_empty_fields() {
    let Sentence::Gga(g) = round_trip(GGA_NO_FIX) else {
        panic!()
    };
    assert_eq!((g.latitude_deg, g.longitude_deg), (None, None));
    assert_eq!((g.fix_quality, g.satellites), (Some(0), Some(0)));
    let Sentence::Rmc(r) = round_trip(RMC_VOID) else {
        panic!()
    };
    assert!(!r.valid);
    assert_eq!(r.mode, Some('N'));
    round_trip(GSA_NO_FIX);

    // A fix, then the receiver loses it: the old position is not kept as if it were valid.
    for lost in [GGA_NO_FIX, RMC_VOID] {
        let fix = applied(&[GGA, RMC, lost]);
        assert_eq!(fix.fix_quality, 0, "{lost}");
        assert!(!fix.has_fix());
        assert_eq!((fix.latitude_deg, fix.longitude_deg), (0.0, 0.0));
        assert_eq!(fix.utc_time_s, 21.0 * 60.0 + 53.0, "the time still counts");
    }
    let fix = applied(&[GSA, GSA_NO_FIX]);
    assert_eq!(fix.fix_type, 1);
    // A void RMC never makes a fix of an empty position.
    let fix = applied(&[RMC_VOID]);
    assert_eq!(fix.fix_quality, 0);
}

#[test]
fn checksums_are_required_and_verified() {
    assert_eq!(
        parse_sentence("$GPVTG,054.7,T,034.4,M,005.5,N,010.2,K*49"),
        Err(DecodeError::BadChecksum {
            expected: 0x48,
            got: 0x49
        })
    );
    // A corrupted character.
    assert!(matches!(
        parse_sentence("$GPVTG,054.7,T,034.4,M,005.5,N,010.3,K*48"),
        Err(DecodeError::BadChecksum { .. })
    ));
    assert!(matches!(
        parse_sentence("$GPVTG,054.7,T,034.4,M,005.5,N,010.2,K"),
        Err(DecodeError::Nmea { reason }) if reason.contains("missing checksum")
    ));
    // Lower-case hex and a CR LF are fine.
    assert_eq!(
        parse_sentence("$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6a\r\n"),
        Ok(parse(RMC))
    );
}

#[test]
fn garbage_and_unsupported_sentences_are_typed_errors() {
    for line in [
        "",
        "$",
        "*",
        "$*00",
        "hello",
        "GPGGA,123519*00",
        "$GPGGA*4",
        "$GPGGA*ZZ",
        "$GPGGA*567",
        "$GPGGA,é*00",
        "$\u{0}*00",
    ] {
        assert!(parse_sentence(line).is_err(), "{line:?}");
    }
    for body in [
        "GPTXT,01,01,02,ANTSTATUS=OK",
        "PSRF103,00,01,00,01",
        "gpGGA,",
        "G1GGA,",
        "GPGGA,123519,4807.038,X,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
        "GPGGA,123519,9107.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
        "GPGGA,123519,4867.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
        "GPGGA,123519,4807.038,N,,E,1,08,0.9,545.4,M,46.9,M,,",
        "GPGGA,253519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
        "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,F,46.9,M,,",
        "GPGGA,123519,4807.038,N,01131.000,E,1,08,inf,545.4,M,46.9,M,,",
        "GPGGA,123519,4807.038,N,01131.000,E,1,08,1e3,545.4,M,46.9,M,,",
        "GPGGA,123519,4807.038,N,01131.000,E,1,-8,0.9,545.4,M,46.9,M,,",
        "GPRMC,123519,X,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W",
        "GPRMC,123519,,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W",
        "GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,231394,003.1,W",
        "GPZDA,201530.00,04,,2002,00,00",
        "GPZDA,201530.00,04,07,2002,14,00",
        "GPGSV,2,1,08,,40,083,46",
        "GPGSV,,1,08",
    ] {
        let line = format!("${body}*{:02X}", checksum(body));
        assert!(
            matches!(parse_sentence(&line), Err(DecodeError::Nmea { .. })),
            "{line}: {:?}",
            parse_sentence(&line)
        );
    }
}

#[test]
fn errors_say_which_field_is_wrong() {
    let body = "GPGGA,123519,4807.038,N,01131.000,E,1,08,abc,545.4,M,46.9,M,,";
    let line = format!("${body}*{:02X}", checksum(body));
    assert_eq!(
        parse_sentence(&line).unwrap_err().to_string(),
        "NMEA: GGA field 8 (HDOP): unexpected 'abc'"
    );
}

#[test]
fn sentences_serialize_with_a_tag_and_the_talker_as_text() {
    let json = serde_json::to_value(parse(VTG)).unwrap();
    assert_eq!(json["sentence"], "vtg");
    assert_eq!(json["talker"], "GP");
    assert_eq!(json["speed_knots"], 5.5);
    assert_eq!(json["mode"], serde_json::Value::Null);
}

#[test]
fn formatting_looks_like_a_receiver() {
    assert_eq!(
        parse(GGA).to_sentence(),
        "$GPGGA,123519.00,4807.0380,N,01131.0000,E,1,08,0.9,545.4,M,46.9,M,,*69"
    );
    assert_eq!(parse(GSV).to_sentence(), GSV);
    assert_eq!(parse(GSA).to_sentence(), GSA);
    assert_eq!(parse(ZDA).to_sentence(), ZDA);
    let rmc = parse(RMC_SYDNEY).to_sentence();
    assert!(rmc.starts_with("$GNRMC,083559.00,A,3352.1280,S,15112.5580,E,0.004,77.52,091202,,,A*"));
    // A simulator's position with more digits than a receiver prints still round-trips.
    let sim = Sentence::Gll(Gll {
        talker: Talker::GPS,
        latitude_deg: Some(-12.345_678_9),
        longitude_deg: Some(-0.000_1),
        time: Some(UtcTime {
            hour: 0,
            minute: 0,
            second: 0.125,
        }),
        valid: Some(true),
        mode: Some('A'),
    });
    let text = sim.to_sentence();
    let Ok(Sentence::Gll(back)) = parse_sentence(&text) else {
        panic!("{text}")
    };
    assert!(close(back.latitude_deg.unwrap(), -12.345_678_9), "{text}");
    assert!(close(back.longitude_deg.unwrap(), -0.000_1), "{text}");
    assert!(text.contains(",W,"), "{text}");
}

// ---------------------------------------------------------------------------------------------
// The line reader.

fn read_all(reader: &mut LineReader, bytes: &[u8], chunk: usize) -> Vec<String> {
    let mut lines = Vec::new();
    for piece in bytes.chunks(chunk.max(1)) {
        reader.push(piece);
        while let Some(line) = reader.next_line() {
            lines.push(line);
        }
    }
    lines
}

#[test]
fn the_line_reader_splits_crlf_lf_and_cr_lines_and_skips_garbage() {
    let stream =
        format!("\u{0}\u{ff}junk{GGA}\r\n{RMC}\n{VTG}\r\r\n\n  {GLL}\r\nhalf-line no dollar\n$GPZ");
    for chunk in [1, 2, 7, 1000] {
        let mut reader = LineReader::new();
        let lines = read_all(&mut reader, stream.as_bytes(), chunk);
        assert_eq!(lines, [GGA, RMC, VTG, GLL], "chunk {chunk}");
        assert_eq!(reader.lines_dropped(), 0);
        // 0x00, U+00FF (2 bytes), "junk", "  " and "half-line no dollar".
        assert_eq!(reader.bytes_discarded(), 1 + 2 + 4 + 2 + 19);
        // "$GPZ" waits for its end.
        reader.push(b"DA\r\n");
        assert_eq!(reader.next_line().as_deref(), Some("$GPZDA"));
    }
}

#[test]
fn overlong_interrupted_and_binary_lines_are_dropped_and_counted() {
    let mut reader = LineReader::with_max_len(82);
    let long = format!("$GPGSV,{}\r\n", "1,".repeat(100));
    let mut stream = long.into_bytes();
    stream.extend(b"$GPGGA,12"); // interrupted by the next '$'
    stream.extend(format!("{GGA}\r\n").as_bytes());
    stream.extend(b"$GP\x01GGA\r\n"); // control character
    stream.extend(b"$GP\xC3\xA9\r\n"); // non-ASCII
    stream.extend(format!("{VTG}\n").as_bytes());
    let lines = read_all(&mut reader, &stream, 5);
    assert_eq!(lines, [GGA, VTG]);
    assert_eq!(reader.lines_dropped(), 4);
}

#[test]
fn the_line_reader_queue_is_bounded() {
    let mut reader = LineReader::new();
    let mut stream = Vec::new();
    for _ in 0..MAX_QUEUED_LINES + 10 {
        stream.extend(format!("{VTG}\r\n").as_bytes());
    }
    reader.push(&stream);
    let mut n = 0;
    while reader.next_line().is_some() {
        n += 1;
    }
    assert_eq!(n, MAX_QUEUED_LINES);
    assert_eq!(reader.lines_dropped(), 10);
}

// ---------------------------------------------------------------------------------------------
// Properties.

fn opt<T: std::fmt::Debug + Clone + 'static>(
    s: impl Strategy<Value = T> + 'static,
) -> impl Strategy<Value = Option<T>> {
    proptest::option::of(s)
}

/// A coordinate as a receiver sends it: whole degrees and minutes with 4-7 decimals.
fn coordinate(max_deg: u16) -> impl Strategy<Value = f64> {
    (0..max_deg, 0u64..60_000_000, any::<bool>()).prop_map(|(deg, micro_min, negative)| {
        let text = format!(
            "{:02}{:02}.{:06}",
            deg,
            micro_min / 1_000_000,
            micro_min % 1_000_000
        );
        let magnitude = super::sentence::parse_ddmm(&text).unwrap();
        if negative { -magnitude } else { magnitude }
    })
}

/// A decimal with up to 3 decimals, as receivers print them.
fn decimal() -> impl Strategy<Value = f64> {
    (-1_000_000i64..1_000_000, 0u32..4).prop_map(|(v, d)| v as f64 / 10f64.powi(d as i32))
}

fn time() -> impl Strategy<Value = UtcTime> {
    (0u8..24, 0u8..60, 0u32..60_000).prop_map(|(hour, minute, ms)| UtcTime {
        hour,
        minute,
        second: f64::from(ms) / 1000.0,
    })
}

fn date() -> impl Strategy<Value = UtcDate> {
    (1980u16..2080, 1u8..=12, 1u8..=31).prop_map(|(year, month, day)| UtcDate { year, month, day })
}

fn letter() -> impl Strategy<Value = char> {
    prop_oneof![Just('A'), Just('D'), Just('E'), Just('N'), Just('M')]
}

fn talker() -> impl Strategy<Value = Talker> {
    prop_oneof![
        Just(Talker::GPS),
        Just(Talker::GNSS),
        Just(Talker::GLONASS),
        Just(Talker::GALILEO),
        Just(Talker::BEIDOU)
    ]
}

fn satellite() -> impl Strategy<Value = SatelliteInView> {
    (1u16..300, opt(0i8..=90), opt(0u16..360), opt(0u8..100)).prop_map(
        |(id, elevation_deg, azimuth_deg, snr_db)| SatelliteInView {
            id,
            elevation_deg,
            azimuth_deg,
            snr_db,
        },
    )
}

fn sentence() -> impl Strategy<Value = Sentence> {
    let gga = (
        talker(),
        opt(time()),
        opt((coordinate(90), coordinate(180))),
        opt(0u8..9),
        opt(0u8..40),
        opt(decimal()),
        opt(decimal()),
        opt(decimal()),
        opt(decimal()),
        opt(0u16..1024),
    )
        .prop_map(
            |(talker, time, pos, q, sats, hdop, alt, geoid, age, station)| {
                Sentence::Gga(Gga {
                    talker,
                    time,
                    latitude_deg: pos.map(|p| p.0),
                    longitude_deg: pos.map(|p| p.1),
                    fix_quality: q,
                    satellites: sats,
                    hdop,
                    altitude_m: alt,
                    geoid_separation_m: geoid,
                    dgps_age_s: age,
                    dgps_station: station,
                })
            },
        );
    let rmc = (
        talker(),
        opt(time()),
        any::<bool>(),
        opt((coordinate(90), coordinate(180))),
        opt(decimal()),
        opt(decimal()),
        opt(date()),
        opt(decimal()),
        opt(letter()),
    )
        .prop_map(
            |(talker, time, valid, pos, speed, course, date, var, mode)| {
                Sentence::Rmc(Rmc {
                    talker,
                    time,
                    valid,
                    latitude_deg: pos.map(|p| p.0),
                    longitude_deg: pos.map(|p| p.1),
                    speed_knots: speed,
                    course_deg: course,
                    date,
                    magnetic_variation_deg: var,
                    mode,
                })
            },
        );
    let vtg = (
        talker(),
        opt(decimal()),
        opt(decimal()),
        opt(decimal()),
        opt(decimal()),
        opt(letter()),
    )
        .prop_map(|(talker, t, m, kn, kmh, mode)| {
            Sentence::Vtg(Vtg {
                talker,
                course_true_deg: t,
                course_magnetic_deg: m,
                speed_knots: kn,
                speed_kmh: kmh,
                mode,
            })
        });
    let gsa = (
        talker(),
        opt(letter()),
        opt(1u8..=3),
        proptest::array::uniform12(opt(1u16..300)),
        opt(decimal()),
        opt(decimal()),
        opt(decimal()),
    )
        .prop_map(|(talker, selection, fix_type, ids, pdop, hdop, vdop)| {
            Sentence::Gsa(Gsa {
                talker,
                selection,
                fix_type,
                satellite_ids: ids,
                pdop,
                hdop,
                vdop,
            })
        });
    let gsv = (
        talker(),
        1u8..10,
        1u8..10,
        opt(0u8..40),
        proptest::array::uniform4(opt(satellite())),
    )
        .prop_map(|(talker, count, number, in_view, satellites)| {
            Sentence::Gsv(Gsv {
                talker,
                message_count: count,
                message_number: number,
                satellites_in_view: in_view,
                satellites,
            })
        });
    let gll = (
        talker(),
        opt((coordinate(90), coordinate(180))),
        opt(time()),
        opt(any::<bool>()),
        opt(letter()),
    )
        .prop_map(|(talker, pos, time, valid, mode)| {
            Sentence::Gll(Gll {
                talker,
                latitude_deg: pos.map(|p| p.0),
                longitude_deg: pos.map(|p| p.1),
                time,
                valid,
                mode,
            })
        });
    let zda = (
        talker(),
        opt(time()),
        opt(date()),
        opt(-13i8..=13),
        opt(0u8..60),
    )
        .prop_map(|(talker, time, date, h, m)| {
            Sentence::Zda(Zda {
                talker,
                time,
                date,
                local_zone_hours: h,
                local_zone_minutes: m,
            })
        });
    prop_oneof![gga, rmc, vtg, gsa, gsv, gll, zda]
}

proptest! {
    #[test]
    fn every_representable_sentence_survives_formatting_and_parsing(s in sentence()) {
        let text = s.to_sentence();
        prop_assert_eq!(parse_sentence(&text), Ok(s), "{}", text);
        prop_assert!(text.len() <= DEFAULT_MAX_LINE_LEN);
    }

    #[test]
    fn arbitrary_text_never_panics(line in "\\PC{0,120}") {
        let _ = parse_sentence(&line);
    }

    #[test]
    fn arbitrary_sentence_like_text_with_a_valid_checksum_never_panics(
        body in "[A-Z]{2}(GGA|RMC|VTG|GSA|GSV|GLL|ZDA)(,[0-9A-Z.+-]{0,12}){0,22}",
    ) {
        let line = format!("${body}*{:02X}", checksum(&body));
        let _ = parse_sentence(&line);
    }

    #[test]
    fn arbitrary_bytes_never_panic_the_line_reader(
        bytes in proptest::collection::vec(
            prop_oneof![any::<u8>(), Just(b'$'), Just(b'\r'), Just(b'\n'), Just(b'*')], 0..2000),
        chunk in 1usize..64,
    ) {
        let mut reader = LineReader::with_max_len(82);
        for line in read_all(&mut reader, &bytes, chunk) {
            prop_assert!(line.starts_with('$') && line.len() <= 82);
            let _ = parse_sentence(&line);
        }
    }

    #[test]
    fn sentences_survive_any_chunking_and_garbage_between_lines(
        sentences in proptest::collection::vec(sentence(), 0..10),
        garbage in proptest::collection::vec("[a-z0-9 ]{0,10}", 10),
        chunk in 1usize..50,
    ) {
        let mut stream = String::new();
        for (s, junk) in sentences.iter().zip(&garbage) {
            stream.push_str(junk);
            stream.push_str(&s.to_sentence());
            stream.push_str("\r\n");
        }
        let mut reader = LineReader::new();
        let parsed: Vec<Sentence> = read_all(&mut reader, stream.as_bytes(), chunk)
            .iter()
            .map(|l| parse_sentence(l).unwrap())
            .collect();
        prop_assert_eq!(parsed, sentences);
        prop_assert_eq!(reader.lines_dropped(), 0);
    }
}
