//! Folding sentences into the published [`GpsFix`].

use chassis_interfaces::GpsFix;

use super::sentence::{Sentence, UtcDate, UtcTime};

/// m/s per knot.
const MPS_PER_KNOT: f64 = 1852.0 / 3600.0;

/// "No fix": quality 0 and the (0, 0) that [`GpsFix`] documents as meaningless, never the last
/// position or the sentence's empty fields.
fn lose_fix(fix: &mut GpsFix) {
    fix.fix_quality = 0;
    fix.latitude_deg = 0.0;
    fix.longitude_deg = 0.0;
}

fn set_time(fix: &mut GpsFix, time: Option<UtcTime>) {
    if let Some(t) = time {
        fix.utc_time_s = t.seconds_of_day();
    }
}

fn set_date(fix: &mut GpsFix, date: Option<UtcDate>) {
    if let Some(d) = date {
        fix.utc_date = d.yyyymmdd();
    }
}

/// A valid position from a sentence without a quality field (RMC, GLL): keep GGA's quality if
/// it has one, else derive it from the mode indicator.
fn set_position(fix: &mut GpsFix, lat: Option<f64>, lon: Option<f64>, mode: Option<char>) {
    if let (Some(lat), Some(lon)) = (lat, lon) {
        fix.latitude_deg = lat;
        fix.longitude_deg = lon;
        if fix.fix_quality == 0 {
            fix.fix_quality = match mode {
                Some('D') => 2,
                Some('R') => 4,
                Some('F') => 5,
                Some('E') => 6,
                _ => 1,
            };
        }
    }
}

/// Updates `fix` with what `sentence` reports; fields the sentence leaves empty keep their
/// value.
///
/// * GGA: time, satellites, HDOP, altitude; quality 0 (or empty) is "no fix" (quality 0,
///   position (0, 0)), else quality and position.
/// * RMC: time, date; status `V` or mode `N` is "no fix", else position, speed (knots → m/s)
///   and course (degrees → rad). GLL likewise, without speed and course.
/// * VTG: speed (knots, or km/h when knots are empty) and true course, unless mode is `N`.
/// * GSA: fix type (1 none, 2 2D, 3 3D; empty → 0 unknown) and HDOP.
/// * ZDA: time and date. GSV: nothing ([`GpsFix`] counts used satellites, not visible ones).
///
/// Sentences without a quality field (RMC, GLL) set quality 1 (2 for mode `D`) only when no GGA
/// has set one.
pub fn apply(sentence: &Sentence, fix: &mut GpsFix) {
    match sentence {
        Sentence::Gga(s) => {
            set_time(fix, s.time);
            match (s.fix_quality, s.latitude_deg, s.longitude_deg) {
                (Some(q), Some(lat), Some(lon)) if q != 0 => {
                    fix.fix_quality = q;
                    fix.latitude_deg = lat;
                    fix.longitude_deg = lon;
                }
                (Some(q), _, _) if q != 0 => fix.fix_quality = q,
                _ => lose_fix(fix),
            }
            if let Some(n) = s.satellites {
                fix.satellites = n;
            }
            if let Some(h) = s.hdop {
                fix.hdop = h as f32;
            }
            if let Some(a) = s.altitude_m {
                fix.altitude_m = a as f32;
            }
        }
        Sentence::Rmc(s) => {
            set_time(fix, s.time);
            set_date(fix, s.date);
            if !s.valid || s.mode == Some('N') {
                lose_fix(fix);
                return;
            }
            set_position(fix, s.latitude_deg, s.longitude_deg, s.mode);
            if let Some(knots) = s.speed_knots {
                fix.speed_mps = (knots * MPS_PER_KNOT) as f32;
            }
            if let Some(course) = s.course_deg {
                fix.course_rad = course.to_radians() as f32;
            }
        }
        Sentence::Vtg(s) => {
            if s.mode == Some('N') {
                return;
            }
            let speed = s
                .speed_knots
                .map(|k| k * MPS_PER_KNOT)
                .or(s.speed_kmh.map(|k| k / 3.6));
            if let Some(v) = speed {
                fix.speed_mps = v as f32;
            }
            if let Some(course) = s.course_true_deg {
                fix.course_rad = course.to_radians() as f32;
            }
        }
        Sentence::Gsa(s) => {
            fix.fix_type = s.fix_type.unwrap_or(0);
            if let Some(h) = s.hdop {
                fix.hdop = h as f32;
            }
        }
        Sentence::Gsv(_) => {}
        Sentence::Gll(s) => {
            set_time(fix, s.time);
            if s.valid == Some(false) || s.mode == Some('N') {
                lose_fix(fix);
                return;
            }
            set_position(fix, s.latitude_deg, s.longitude_deg, s.mode);
        }
        Sentence::Zda(s) => {
            set_time(fix, s.time);
            set_date(fix, s.date);
        }
    }
}
