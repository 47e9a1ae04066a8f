//! Typed NMEA 0183 sentences: parsing and formatting.
//!
//! Values are kept as the sentence gives them, with coordinates already in signed decimal
//! degrees (north and east positive). Formatting picks, for every decimal field, the fewest
//! digits that parse back to the same `f64`, so `parse_sentence(&s.to_sentence()) == Ok(s)` for
//! every sentence that came from [`parse_sentence`] (and for any value a receiver could send).

use std::fmt::{self, Write as _};

use serde::{Serialize, Serializer};

use crate::DecodeError;

/// Two-letter talker id (`GP` GPS, `GN` combined GNSS, `GL` GLONASS, `GA` Galileo, `GB`/`BD`
/// BeiDou, …): two upper-case ASCII letters.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Talker([u8; 2]);

impl Talker {
    pub const GPS: Talker = Talker(*b"GP");
    pub const GNSS: Talker = Talker(*b"GN");
    pub const GLONASS: Talker = Talker(*b"GL");
    pub const GALILEO: Talker = Talker(*b"GA");
    pub const BEIDOU: Talker = Talker(*b"GB");

    /// `None` unless `text` is two upper-case ASCII letters.
    pub fn new(text: &str) -> Option<Talker> {
        match text.as_bytes() {
            &[a, b] if a.is_ascii_uppercase() && b.is_ascii_uppercase() => Some(Talker([a, b])),
            _ => None,
        }
    }

    pub fn as_str(&self) -> &str {
        // Two ASCII letters, checked on construction.
        std::str::from_utf8(&self.0).unwrap_or("??")
    }
}

impl fmt::Debug for Talker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Talker({})", self.as_str())
    }
}

impl fmt::Display for Talker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for Talker {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

/// UTC time of day, `hhmmss.sss`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct UtcTime {
    /// 0-23.
    pub hour: u8,
    /// 0-59.
    pub minute: u8,
    /// 0 to below 61 (a leap second reads 60.x).
    pub second: f64,
}

impl UtcTime {
    /// Seconds since midnight.
    pub fn seconds_of_day(&self) -> f64 {
        f64::from(self.hour) * 3600.0 + f64::from(self.minute) * 60.0 + self.second
    }

    fn is_valid(&self) -> bool {
        self.hour < 24 && self.minute < 60 && (0.0..61.0).contains(&self.second)
    }
}

/// UTC date.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct UtcDate {
    /// Four digits. RMC's two-digit year reads as 1980-2079.
    pub year: u16,
    /// 1-12.
    pub month: u8,
    /// 1-31.
    pub day: u8,
}

impl UtcDate {
    /// As `GpsFix::utc_date`: `yyyymmdd`.
    pub fn yyyymmdd(&self) -> u32 {
        u32::from(self.year) * 10_000 + u32::from(self.month) * 100 + u32::from(self.day)
    }

    fn is_valid(&self) -> bool {
        self.year <= 9999 && (1..=12).contains(&self.month) && (1..=31).contains(&self.day)
    }
}

/// GGA: fix data.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Gga {
    pub talker: Talker,
    pub time: Option<UtcTime>,
    /// Degrees, north positive.
    pub latitude_deg: Option<f64>,
    /// Degrees, east positive.
    pub longitude_deg: Option<f64>,
    /// 0 = no fix, 1 = GPS, 2 = DGPS, 4 = RTK fixed, 5 = RTK float, 6 = estimated, …
    pub fix_quality: Option<u8>,
    /// Satellites used.
    pub satellites: Option<u8>,
    pub hdop: Option<f64>,
    /// Antenna altitude above mean sea level, m.
    pub altitude_m: Option<f64>,
    /// Geoid height above the WGS84 ellipsoid, m.
    pub geoid_separation_m: Option<f64>,
    /// Age of the differential corrections, s.
    pub dgps_age_s: Option<f64>,
    /// Differential reference station id, 0-1023.
    pub dgps_station: Option<u16>,
}

/// RMC: recommended minimum data.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Rmc {
    pub talker: Talker,
    pub time: Option<UtcTime>,
    /// Status `A` (true) or `V` (false, "void": no fix).
    pub valid: bool,
    pub latitude_deg: Option<f64>,
    pub longitude_deg: Option<f64>,
    /// Speed over ground, knots.
    pub speed_knots: Option<f64>,
    /// Course over ground, degrees clockwise from true north.
    pub course_deg: Option<f64>,
    pub date: Option<UtcDate>,
    /// Magnetic variation, degrees, east positive.
    pub magnetic_variation_deg: Option<f64>,
    /// Mode indicator (NMEA 2.3+): `A` autonomous, `D` differential, `E` estimated, `N` not
    /// valid, …
    pub mode: Option<char>,
}

/// VTG: course and speed over ground.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Vtg {
    pub talker: Talker,
    /// Degrees clockwise from true north.
    pub course_true_deg: Option<f64>,
    /// Degrees clockwise from magnetic north.
    pub course_magnetic_deg: Option<f64>,
    pub speed_knots: Option<f64>,
    pub speed_kmh: Option<f64>,
    pub mode: Option<char>,
}

/// GSA: DOP and active satellites.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Gsa {
    pub talker: Talker,
    /// `A` automatic or `M` manual 2D/3D selection.
    pub selection: Option<char>,
    /// 1 = no fix, 2 = 2D, 3 = 3D.
    pub fix_type: Option<u8>,
    /// Ids of the satellites used, 12 slots.
    pub satellite_ids: [Option<u16>; 12],
    pub pdop: Option<f64>,
    pub hdop: Option<f64>,
    pub vdop: Option<f64>,
}

/// One satellite of a GSV sentence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct SatelliteInView {
    pub id: u16,
    /// Degrees, 0-90.
    pub elevation_deg: Option<i8>,
    /// Degrees, 0-359.
    pub azimuth_deg: Option<u16>,
    /// C/N0, dB-Hz; empty when not tracked.
    pub snr_db: Option<u8>,
}

/// GSV: satellites in view, up to four per sentence.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Gsv {
    pub talker: Talker,
    /// Number of GSV sentences in this cycle.
    pub message_count: u8,
    /// This sentence's number, from 1.
    pub message_number: u8,
    pub satellites_in_view: Option<u8>,
    pub satellites: [Option<SatelliteInView>; 4],
}

/// GLL: geographic position.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Gll {
    pub talker: Talker,
    pub latitude_deg: Option<f64>,
    pub longitude_deg: Option<f64>,
    pub time: Option<UtcTime>,
    /// Status `A` (true) or `V` (false); absent before NMEA 2.0.
    pub valid: Option<bool>,
    pub mode: Option<char>,
}

/// ZDA: UTC date and time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Zda {
    pub talker: Talker,
    pub time: Option<UtcTime>,
    pub date: Option<UtcDate>,
    /// Local zone hours, -13 to 13.
    pub local_zone_hours: Option<i8>,
    /// Local zone minutes, 0-59.
    pub local_zone_minutes: Option<u8>,
}

/// Every sentence this module reads.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "sentence", rename_all = "snake_case")]
pub enum Sentence {
    Gga(Gga),
    Rmc(Rmc),
    Vtg(Vtg),
    Gsa(Gsa),
    Gsv(Gsv),
    Gll(Gll),
    Zda(Zda),
}

// ---------------------------------------------------------------------------------------------
// Parsing.

fn nmea_error(reason: impl Into<String>) -> DecodeError {
    DecodeError::Nmea {
        reason: reason.into(),
    }
}

/// The XOR of the characters between `$` and `*`.
pub fn checksum(body: &str) -> u8 {
    body.bytes().fold(0, |acc, b| acc ^ b)
}

/// `ddd`/`dd.ddd`/`-dd.d` (no exponent, no `inf`/`NaN`): the only number forms NMEA uses.
fn parse_decimal(text: &str) -> Option<f64> {
    let digits = text.strip_prefix(['-', '+']).unwrap_or(text);
    let well_formed = !digits.is_empty()
        && digits.bytes().any(|b| b.is_ascii_digit())
        && digits.bytes().all(|b| b.is_ascii_digit() || b == b'.')
        && digits.bytes().filter(|&b| b == b'.').count() <= 1;
    if !well_formed {
        return None;
    }
    text.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// The comma-separated fields of one sentence, field 0 being the address (`GPGGA`).
struct Fields<'a> {
    kind: &'static str,
    fields: Vec<&'a str>,
}

impl<'a> Fields<'a> {
    /// Field `i`, empty when the sentence is shorter.
    fn get(&self, i: usize) -> &'a str {
        self.fields.get(i).copied().unwrap_or("")
    }

    fn bad(&self, i: usize, what: &str) -> DecodeError {
        nmea_error(format!(
            "{} field {i} ({what}): unexpected '{}'",
            self.kind,
            self.get(i)
        ))
    }

    fn decimal(&self, i: usize, what: &str) -> Result<Option<f64>, DecodeError> {
        match self.get(i) {
            "" => Ok(None),
            text => parse_decimal(text)
                .map(Some)
                .ok_or_else(|| self.bad(i, what)),
        }
    }

    /// An unsigned integer (digits only).
    fn uint<T: std::str::FromStr>(&self, i: usize, what: &str) -> Result<Option<T>, DecodeError> {
        match self.get(i) {
            "" => Ok(None),
            text if text.bytes().all(|b| b.is_ascii_digit()) => {
                text.parse().map(Some).map_err(|_| self.bad(i, what))
            }
            _ => Err(self.bad(i, what)),
        }
    }

    /// A signed integer.
    fn int<T: std::str::FromStr>(&self, i: usize, what: &str) -> Result<Option<T>, DecodeError> {
        let text = self.get(i);
        let digits = text.strip_prefix(['-', '+']).unwrap_or(text);
        match text {
            "" => Ok(None),
            _ if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) => {
                text.parse().map(Some).map_err(|_| self.bad(i, what))
            }
            _ => Err(self.bad(i, what)),
        }
    }

    fn required<T>(&self, i: usize, what: &str, value: Option<T>) -> Result<T, DecodeError> {
        value.ok_or_else(|| self.bad(i, what))
    }

    /// A one-letter field (mode indicators, selection mode).
    fn letter(&self, i: usize, what: &str) -> Result<Option<char>, DecodeError> {
        match self.get(i).as_bytes() {
            [] => Ok(None),
            &[c] if c.is_ascii_uppercase() => Ok(Some(char::from(c))),
            _ => Err(self.bad(i, what)),
        }
    }

    /// Status `A`/`V`.
    fn status(&self, i: usize) -> Result<Option<bool>, DecodeError> {
        match self.get(i) {
            "" => Ok(None),
            "A" => Ok(Some(true)),
            "V" => Ok(Some(false)),
            _ => Err(self.bad(i, "status")),
        }
    }

    /// A unit letter after a value: empty or `expected`.
    fn unit(&self, i: usize, expected: &str) -> Result<(), DecodeError> {
        match self.get(i) {
            "" => Ok(()),
            t if t == expected => Ok(()),
            _ => Err(self.bad(i, "unit")),
        }
    }

    /// `hhmmss` or `hhmmss.sss`.
    fn time(&self, i: usize) -> Result<Option<UtcTime>, DecodeError> {
        let text = self.get(i);
        if text.is_empty() {
            return Ok(None);
        }
        let parsed = (|| {
            let digits = text.get(..6)?;
            if !digits.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            let time = UtcTime {
                hour: digits.get(..2)?.parse().ok()?,
                minute: digits.get(2..4)?.parse().ok()?,
                second: parse_decimal(text.get(4..)?)?,
            };
            time.is_valid().then_some(time)
        })();
        parsed.map(Some).ok_or_else(|| self.bad(i, "time"))
    }

    /// RMC's `ddmmyy`; the two-digit year reads as 1980-2079.
    fn date_ddmmyy(&self, i: usize) -> Result<Option<UtcDate>, DecodeError> {
        let text = self.get(i);
        if text.is_empty() {
            return Ok(None);
        }
        let parsed = (|| {
            if text.len() != 6 || !text.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            let yy: u16 = text.get(4..6)?.parse().ok()?;
            let date = UtcDate {
                day: text.get(..2)?.parse().ok()?,
                month: text.get(2..4)?.parse().ok()?,
                year: if yy < 80 { 2000 + yy } else { 1900 + yy },
            };
            date.is_valid().then_some(date)
        })();
        parsed.map(Some).ok_or_else(|| self.bad(i, "date"))
    }

    /// `ddmm.mmmm` (latitude, `max_deg` 90) or `dddmm.mmmm` (longitude, 180) in field `i` and
    /// its hemisphere letter in field `i + 1`; both empty is `None`.
    fn coordinate(
        &self,
        i: usize,
        max_deg: f64,
        hemispheres: [&str; 2],
    ) -> Result<Option<f64>, DecodeError> {
        let (text, hemisphere) = (self.get(i), self.get(i + 1));
        if text.is_empty() && hemisphere.is_empty() {
            return Ok(None);
        }
        let what = if max_deg == 90.0 {
            "latitude"
        } else {
            "longitude"
        };
        let sign = match hemisphere {
            h if h == hemispheres[0] => 1.0,
            h if h == hemispheres[1] => -1.0,
            _ => return Err(self.bad(i + 1, what)),
        };
        let magnitude = parse_ddmm(text)
            .filter(|&deg| deg <= max_deg)
            .ok_or_else(|| self.bad(i, what))?;
        Ok(Some(sign * magnitude))
    }
}

/// `ddmm.mmmm` → degrees: the digits before the last two of the integer part are degrees, the
/// rest minutes (below 60).
pub(super) fn parse_ddmm(text: &str) -> Option<f64> {
    let int_len = text.find('.').unwrap_or(text.len());
    if int_len < 3 || !text.get(..int_len)?.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let degrees: u16 = text.get(..int_len - 2)?.parse().ok()?;
    let minutes = parse_decimal(text.get(int_len - 2..)?)?;
    (minutes < 60.0).then(|| f64::from(degrees) + minutes / 60.0)
}

/// Parses one sentence: `$`, address, fields, `*hh`; surrounding whitespace (CR LF) is ignored.
pub fn parse_sentence(line: &str) -> Result<Sentence, DecodeError> {
    let line = line.trim();
    let rest = line
        .strip_prefix('$')
        .ok_or_else(|| nmea_error("sentence does not start with '$'"))?;
    let (body, hex) = rest
        .rsplit_once('*')
        .ok_or_else(|| nmea_error("missing checksum"))?;
    let got = match hex.as_bytes() {
        [a, b] if a.is_ascii_hexdigit() && b.is_ascii_hexdigit() => {
            u8::from_str_radix(hex, 16).map_err(|_| nmea_error("malformed checksum"))?
        }
        _ => return Err(nmea_error(format!("malformed checksum '{hex}'"))),
    };
    let expected = checksum(body);
    if got != expected {
        return Err(DecodeError::BadChecksum { expected, got });
    }
    if !body.bytes().all(|b| (0x20..=0x7E).contains(&b)) {
        return Err(nmea_error("non-printable character in sentence"));
    }
    let fields: Vec<&str> = body.split(',').collect();
    let address = fields.first().copied().unwrap_or("");
    let (talker, kind) = match (address.get(..2), address.get(2..)) {
        (Some(t), Some(k)) if address.len() == 5 => (Talker::new(t), k),
        _ => (None, ""),
    };
    let talker =
        talker.ok_or_else(|| nmea_error(format!("unsupported sentence address '{address}'")))?;
    let kind: &'static str = match kind {
        "GGA" => "GGA",
        "RMC" => "RMC",
        "VTG" => "VTG",
        "GSA" => "GSA",
        "GSV" => "GSV",
        "GLL" => "GLL",
        "ZDA" => "ZDA",
        _ => return Err(nmea_error(format!("unsupported sentence type '{address}'"))),
    };
    let f = Fields { kind, fields };
    let sentence = match kind {
        "GGA" => {
            f.unit(10, "M")?;
            f.unit(12, "M")?;
            Sentence::Gga(Gga {
                talker,
                time: f.time(1)?,
                latitude_deg: f.coordinate(2, 90.0, ["N", "S"])?,
                longitude_deg: f.coordinate(4, 180.0, ["E", "W"])?,
                fix_quality: f.uint(6, "fix quality")?,
                satellites: f.uint(7, "satellites")?,
                hdop: f.decimal(8, "HDOP")?,
                altitude_m: f.decimal(9, "altitude")?,
                geoid_separation_m: f.decimal(11, "geoid separation")?,
                dgps_age_s: f.decimal(13, "DGPS age")?,
                dgps_station: f.uint(14, "DGPS station")?,
            })
        }
        "RMC" => {
            let variation = f.decimal(10, "magnetic variation")?;
            let variation_sign = match f.get(11) {
                "E" | "" => 1.0,
                "W" => -1.0,
                _ => return Err(f.bad(11, "variation direction")),
            };
            Sentence::Rmc(Rmc {
                talker,
                time: f.time(1)?,
                valid: f.required(2, "status", f.status(2)?)?,
                latitude_deg: f.coordinate(3, 90.0, ["N", "S"])?,
                longitude_deg: f.coordinate(5, 180.0, ["E", "W"])?,
                speed_knots: f.decimal(7, "speed")?,
                course_deg: f.decimal(8, "course")?,
                date: f.date_ddmmyy(9)?,
                magnetic_variation_deg: variation.map(|v| variation_sign * v),
                mode: f.letter(12, "mode")?,
            })
        }
        "VTG" => {
            f.unit(2, "T")?;
            f.unit(4, "M")?;
            f.unit(6, "N")?;
            f.unit(8, "K")?;
            Sentence::Vtg(Vtg {
                talker,
                course_true_deg: f.decimal(1, "true course")?,
                course_magnetic_deg: f.decimal(3, "magnetic course")?,
                speed_knots: f.decimal(5, "speed in knots")?,
                speed_kmh: f.decimal(7, "speed in km/h")?,
                mode: f.letter(9, "mode")?,
            })
        }
        "GSA" => {
            let mut satellite_ids = [None; 12];
            for (slot, id) in satellite_ids.iter_mut().enumerate() {
                *id = f.uint(3 + slot, "satellite id")?;
            }
            Sentence::Gsa(Gsa {
                talker,
                selection: f.letter(1, "selection mode")?,
                fix_type: f.uint(2, "fix type")?,
                satellite_ids,
                pdop: f.decimal(15, "PDOP")?,
                hdop: f.decimal(16, "HDOP")?,
                vdop: f.decimal(17, "VDOP")?,
            })
        }
        "GSV" => {
            // Fields after the first three come in fours; one extra is NMEA 4.11's signal id.
            let n = f.fields.len().saturating_sub(4);
            let blocks = if n % 4 == 1 { n / 4 } else { n.div_ceil(4) }.min(4);
            let mut satellites = [None; 4];
            for (block, slot) in satellites.iter_mut().enumerate().take(blocks) {
                let i = 4 + 4 * block;
                let id = f.uint(i, "satellite id")?;
                let elevation_deg = f.int(i + 1, "elevation")?;
                let azimuth_deg = f.uint(i + 2, "azimuth")?;
                let snr_db = f.uint(i + 3, "SNR")?;
                *slot = match id {
                    Some(id) => Some(SatelliteInView {
                        id,
                        elevation_deg,
                        azimuth_deg,
                        snr_db,
                    }),
                    None if elevation_deg.is_none()
                        && azimuth_deg.is_none()
                        && snr_db.is_none() =>
                    {
                        None
                    }
                    None => return Err(f.bad(i, "satellite id")),
                };
            }
            Sentence::Gsv(Gsv {
                talker,
                message_count: f.required(1, "message count", f.uint(1, "message count")?)?,
                message_number: f.required(2, "message number", f.uint(2, "message number")?)?,
                satellites_in_view: f.uint(3, "satellites in view")?,
                satellites,
            })
        }
        "GLL" => Sentence::Gll(Gll {
            talker,
            latitude_deg: f.coordinate(1, 90.0, ["N", "S"])?,
            longitude_deg: f.coordinate(3, 180.0, ["E", "W"])?,
            time: f.time(5)?,
            valid: f.status(6)?,
            mode: f.letter(7, "mode")?,
        }),
        _ => {
            // ZDA.
            let day: Option<u8> = f.uint(2, "day")?;
            let month: Option<u8> = f.uint(3, "month")?;
            let year: Option<u16> = f.uint(4, "year")?;
            let date = match (day, month, year) {
                (None, None, None) => None,
                (Some(day), Some(month), Some(year)) => {
                    let date = UtcDate { year, month, day };
                    if !date.is_valid() {
                        return Err(f.bad(2, "date"));
                    }
                    Some(date)
                }
                _ => return Err(f.bad(2, "incomplete date")),
            };
            let local_zone_hours: Option<i8> = f.int(5, "local zone hours")?;
            if local_zone_hours.is_some_and(|h| !(-13..=13).contains(&h)) {
                return Err(f.bad(5, "local zone hours"));
            }
            let local_zone_minutes: Option<u8> = f.uint(6, "local zone minutes")?;
            if local_zone_minutes.is_some_and(|m| m > 59) {
                return Err(f.bad(6, "local zone minutes"));
            }
            Sentence::Zda(Zda {
                talker,
                time: f.time(1)?,
                date,
                local_zone_hours,
                local_zone_minutes,
            })
        }
    };
    Ok(sentence)
}

// ---------------------------------------------------------------------------------------------
// Formatting.

/// The shortest decimal text that parses back to `v` (Rust's `Display` never uses an
/// exponent), with `.0` added to whole numbers as receivers print them.
fn fmt_decimal(out: &mut String, v: Option<f64>) {
    if let Some(v) = v.filter(|v| v.is_finite()) {
        let text = v.to_string();
        out.push_str(&text);
        if !text.contains('.') {
            out.push_str(".0");
        }
    }
}

/// `value` with `decimals` decimals, zero-padded to `int_digits` integer digits.
fn fixed(value: f64, int_digits: usize, decimals: usize) -> String {
    let width = int_digits + if decimals > 0 { decimals + 1 } else { 0 };
    format!("{value:0width$.decimals$}")
}

/// `(d)ddmm.mmmm` and its hemisphere, with the fewest minute decimals (at least 4) that parse
/// back to `deg`. Empty fields for `None` or a value outside ±`max_deg`.
fn fmt_coordinate(
    out: &mut String,
    deg: Option<f64>,
    deg_digits: usize,
    max_deg: f64,
    hemispheres: [char; 2],
) {
    let Some(deg) = deg.filter(|d| d.is_finite() && d.abs() <= max_deg) else {
        out.push(',');
        return;
    };
    let magnitude = deg.abs();
    let whole = magnitude.trunc();
    let minutes = (magnitude - whole) * 60.0;
    let mut best = String::new();
    for decimals in 4..=12 {
        let (degrees, text) = match fixed(minutes, 2, decimals) {
            // Rounded up to a whole degree.
            text if text.starts_with("60") => (whole + 1.0, fixed(0.0, 2, decimals)),
            text => (whole, text),
        };
        best = format!("{}{text}", fixed(degrees, deg_digits, 0));
        if parse_ddmm(&best) == Some(magnitude) {
            break;
        }
    }
    out.push_str(&best);
    out.push(',');
    out.push(if deg.is_sign_negative() && deg != 0.0 {
        hemispheres[1]
    } else {
        hemispheres[0]
    });
}

/// `hhmmss.ss` with the fewest second decimals (at least 2) that parse back; empty for `None`
/// or an invalid time.
fn fmt_time(out: &mut String, time: Option<UtcTime>) {
    let Some(t) = time.filter(UtcTime::is_valid) else {
        return;
    };
    let mut seconds = String::new();
    for decimals in 2..=9 {
        seconds = fixed(t.second, 2, decimals);
        if parse_decimal(&seconds) == Some(t.second) {
            break;
        }
    }
    let _ = write!(out, "{:02}{:02}{seconds}", t.hour, t.minute);
}

fn fmt_opt<T: fmt::Display>(out: &mut String, v: Option<T>, width: usize) {
    if let Some(v) = v {
        let _ = write!(out, "{v:0width$}");
    }
}

fn fmt_letter(out: &mut String, c: Option<char>) {
    if let Some(c) = c.filter(char::is_ascii_uppercase) {
        out.push(c);
    }
}

fn fmt_status(out: &mut String, valid: Option<bool>) {
    match valid {
        Some(true) => out.push('A'),
        Some(false) => out.push('V'),
        None => {}
    }
}

impl Sentence {
    /// The talker id.
    pub fn talker(&self) -> Talker {
        match self {
            Sentence::Gga(s) => s.talker,
            Sentence::Rmc(s) => s.talker,
            Sentence::Vtg(s) => s.talker,
            Sentence::Gsa(s) => s.talker,
            Sentence::Gsv(s) => s.talker,
            Sentence::Gll(s) => s.talker,
            Sentence::Zda(s) => s.talker,
        }
    }

    /// The three-letter sentence type, `"GGA"`.
    pub fn kind(&self) -> &'static str {
        match self {
            Sentence::Gga(_) => "GGA",
            Sentence::Rmc(_) => "RMC",
            Sentence::Vtg(_) => "VTG",
            Sentence::Gsa(_) => "GSA",
            Sentence::Gsv(_) => "GSV",
            Sentence::Gll(_) => "GLL",
            Sentence::Zda(_) => "ZDA",
        }
    }

    /// The sentence as a receiver sends it: `$`, fields, `*hh` (upper-case hex), without the
    /// trailing CR LF. Values a receiver could not send (NaN, a latitude beyond 90°, an invalid
    /// time) come out as empty fields.
    pub fn to_sentence(&self) -> String {
        let mut b = format!("{}{}", self.talker(), self.kind());
        let o = &mut b;
        match self {
            Sentence::Gga(s) => {
                o.push(',');
                fmt_time(o, s.time);
                o.push(',');
                fmt_coordinate(o, s.latitude_deg, 2, 90.0, ['N', 'S']);
                o.push(',');
                fmt_coordinate(o, s.longitude_deg, 3, 180.0, ['E', 'W']);
                o.push(',');
                fmt_opt(o, s.fix_quality, 1);
                o.push(',');
                fmt_opt(o, s.satellites, 2);
                o.push(',');
                fmt_decimal(o, s.hdop);
                o.push(',');
                fmt_decimal(o, s.altitude_m);
                o.push_str(",M,");
                fmt_decimal(o, s.geoid_separation_m);
                o.push_str(",M,");
                fmt_decimal(o, s.dgps_age_s);
                o.push(',');
                fmt_opt(o, s.dgps_station, 4);
            }
            Sentence::Rmc(s) => {
                o.push(',');
                fmt_time(o, s.time);
                o.push(',');
                fmt_status(o, Some(s.valid));
                o.push(',');
                fmt_coordinate(o, s.latitude_deg, 2, 90.0, ['N', 'S']);
                o.push(',');
                fmt_coordinate(o, s.longitude_deg, 3, 180.0, ['E', 'W']);
                o.push(',');
                fmt_decimal(o, s.speed_knots);
                o.push(',');
                fmt_decimal(o, s.course_deg);
                o.push(',');
                if let Some(d) = s
                    .date
                    .filter(|d| d.is_valid() && (1980..2080).contains(&d.year))
                {
                    let _ = write!(o, "{:02}{:02}{:02}", d.day, d.month, d.year % 100);
                }
                o.push(',');
                let variation = s.magnetic_variation_deg.filter(|v| v.is_finite());
                fmt_decimal(o, variation.map(f64::abs));
                o.push(',');
                match variation {
                    Some(v) if v.is_sign_negative() && v != 0.0 => o.push('W'),
                    Some(_) => o.push('E'),
                    None => {}
                }
                o.push(',');
                fmt_letter(o, s.mode);
            }
            Sentence::Vtg(s) => {
                o.push(',');
                fmt_decimal(o, s.course_true_deg);
                o.push_str(",T,");
                fmt_decimal(o, s.course_magnetic_deg);
                o.push_str(",M,");
                fmt_decimal(o, s.speed_knots);
                o.push_str(",N,");
                fmt_decimal(o, s.speed_kmh);
                o.push_str(",K,");
                fmt_letter(o, s.mode);
            }
            Sentence::Gsa(s) => {
                o.push(',');
                fmt_letter(o, s.selection);
                o.push(',');
                fmt_opt(o, s.fix_type, 1);
                for id in s.satellite_ids {
                    o.push(',');
                    fmt_opt(o, id, 2);
                }
                for dop in [s.pdop, s.hdop, s.vdop] {
                    o.push(',');
                    fmt_decimal(o, dop);
                }
            }
            Sentence::Gsv(s) => {
                let _ = write!(o, ",{},{},", s.message_count, s.message_number);
                fmt_opt(o, s.satellites_in_view, 2);
                let used = s
                    .satellites
                    .iter()
                    .rposition(Option::is_some)
                    .map_or(0, |i| i + 1);
                for sat in s.satellites.iter().take(used) {
                    match sat {
                        Some(sat) => {
                            let _ = write!(o, ",{:02},", sat.id);
                            fmt_opt(o, sat.elevation_deg, 2);
                            o.push(',');
                            fmt_opt(o, sat.azimuth_deg, 3);
                            o.push(',');
                            fmt_opt(o, sat.snr_db, 2);
                        }
                        None => o.push_str(",,,,"),
                    }
                }
            }
            Sentence::Gll(s) => {
                o.push(',');
                fmt_coordinate(o, s.latitude_deg, 2, 90.0, ['N', 'S']);
                o.push(',');
                fmt_coordinate(o, s.longitude_deg, 3, 180.0, ['E', 'W']);
                o.push(',');
                fmt_time(o, s.time);
                o.push(',');
                fmt_status(o, s.valid);
                o.push(',');
                fmt_letter(o, s.mode);
            }
            Sentence::Zda(s) => {
                o.push(',');
                fmt_time(o, s.time);
                match s.date.filter(UtcDate::is_valid) {
                    Some(d) => {
                        let _ = write!(o, ",{:02},{:02},{:04}", d.day, d.month, d.year);
                    }
                    None => o.push_str(",,,"),
                }
                o.push(',');
                fmt_opt(o, s.local_zone_hours.filter(|h| (-13..=13).contains(h)), 2);
                o.push(',');
                fmt_opt(o, s.local_zone_minutes.filter(|&m| m < 60), 2);
            }
        }
        let sum = checksum(&b);
        format!("${b}*{sum:02X}")
    }
}
