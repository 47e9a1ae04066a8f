//! Waypoint files, in metres in the frame of the robot's start pose (x ahead, y left).
//!
//! CSV — two columns `x,y`, an optional header naming them (in any order, other columns
//! ignored), blank lines and whole-line `#` comments allowed:
//!
//! ```text
//! # two metres ahead, then 1.5 m to the left
//! x,y
//! 0,0
//! 2,0
//! 2,1.5
//! ```
//!
//! A path that does not start at the robot (its first waypoint farther than the goal
//! tolerance from `0,0`) is driven from the robot's position to it first.
//!
//! TOML — an array of tables:
//!
//! ```toml
//! [[waypoint]]
//! x = 0.0
//! y = 0.0
//!
//! [[waypoint]]
//! x = 2
//! y = 0
//! ```
//!
//! A file ending in `.toml` is TOML, anything else CSV. Errors name the line.

use std::path::Path as FsPath;

use serde::Deserialize;
use thiserror::Error;

use crate::geometry::Point;

/// Why a waypoint file cannot be read.
#[derive(Debug, Error)]
pub enum WaypointError {
    #[error("reading {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("line {line}: {message}")]
    Line { line: u64, message: String },
    #[error("{0}")]
    Toml(String),
    #[error("a path needs at least two waypoints (the file has {0})")]
    TooFew(usize),
}

/// Reads a waypoint file (CSV or TOML by its extension).
pub fn read(path: &FsPath) -> Result<Vec<Point>, WaypointError> {
    let text = std::fs::read_to_string(path).map_err(|source| WaypointError::Read {
        path: path.display().to_string(),
        source,
    })?;
    let is_toml = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"));
    if is_toml {
        parse_toml(&text)
    } else {
        parse_csv(&text)
    }
}

/// Parses CSV waypoints.
pub fn parse_csv(text: &str) -> Result<Vec<Point>, WaypointError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    let mut columns: Option<(usize, usize)> = None;
    let mut points = Vec::new();
    for (index, record) in reader.records().enumerate() {
        // The reader's own line count skips blank lines: count from the byte offset.
        let record = record.map_err(|e| WaypointError::Line {
            line: e
                .position()
                .map_or(0, |p| line_of(text, byte_offset(text, p))),
            message: e.to_string(),
        })?;
        let line = record
            .position()
            .map_or(0, |p| line_of(text, byte_offset(text, p)));
        let fields: Vec<&str> = record.iter().collect();
        if fields.iter().all(|f| f.is_empty()) {
            continue;
        }
        if index == 0 && columns.is_none() && fields.iter().any(|f| f.parse::<f64>().is_err()) {
            // A header: the first line, not all numbers.
            let find = |name: &str| fields.iter().position(|f| f.eq_ignore_ascii_case(name));
            match (find("x"), find("y")) {
                (Some(x), Some(y)) => {
                    columns = Some((x, y));
                    continue;
                }
                _ => {
                    return Err(WaypointError::Line {
                        line,
                        message: format!(
                            "expected numbers x,y or a header naming columns x and y, found '{}'",
                            fields.join(",")
                        ),
                    });
                }
            }
        }
        let (xi, yi) = columns.unwrap_or((0, 1));
        let needed = xi.max(yi) + 1;
        if fields.len() < needed || (columns.is_none() && fields.len() != 2) {
            return Err(WaypointError::Line {
                line,
                message: format!(
                    "expected {} columns x,y, found {}",
                    if columns.is_some() { needed } else { 2 },
                    fields.len()
                ),
            });
        }
        let number = |i: usize, name: &str| -> Result<f64, WaypointError> {
            let field = fields[i];
            match field.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                Ok(_) => Err(WaypointError::Line {
                    line,
                    message: format!("{name} = '{field}' is not a finite number"),
                }),
                Err(_) => Err(WaypointError::Line {
                    line,
                    message: format!("{name} = '{field}' is not a number"),
                }),
            }
        };
        points.push(Point::new(number(xi, "x")?, number(yi, "y")?));
    }
    if points.len() < 2 {
        return Err(WaypointError::TooFew(points.len()));
    }
    Ok(points)
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlFile {
    #[serde(default)]
    waypoint: Vec<toml::Spanned<TomlWaypoint>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlWaypoint {
    x: f64,
    y: f64,
}

/// Where a CSV record starts: the reader's offset points before the blank and comment lines
/// it skipped.
fn byte_offset(text: &str, position: &csv::Position) -> usize {
    let mut offset = usize::try_from(position.byte()).unwrap_or(usize::MAX);
    while let Some(rest) = text.get(offset..) {
        let line = rest.split('\n').next().unwrap_or("");
        let skipped = line.trim().is_empty() || line.trim_start().starts_with('#');
        if !skipped || line.len() == rest.len() {
            break;
        }
        offset += line.len() + 1;
    }
    offset
}

/// The 1-based line holding byte `offset` of `text`.
fn line_of(text: &str, offset: usize) -> u64 {
    let before = text.get(..offset.min(text.len())).unwrap_or(text);
    before.bytes().filter(|&b| b == b'\n').count() as u64 + 1
}

/// Parses TOML waypoints (`[[waypoint]]` tables with `x` and `y`).
pub fn parse_toml(text: &str) -> Result<Vec<Point>, WaypointError> {
    let file: TomlFile = toml::from_str(text).map_err(|e| match e.span() {
        Some(span) => WaypointError::Line {
            line: line_of(text, span.start),
            message: e.message().trim_end().to_string(),
        },
        None => WaypointError::Toml(e.to_string()),
    })?;
    let mut points = Vec::with_capacity(file.waypoint.len());
    for w in &file.waypoint {
        let p = Point::new(w.get_ref().x, w.get_ref().y);
        if !p.is_finite() {
            return Err(WaypointError::Line {
                line: line_of(text, w.span().start),
                message: "waypoint coordinates must be finite numbers".into(),
            });
        }
        points.push(p);
    }
    if points.len() < 2 {
        return Err(WaypointError::TooFew(points.len()));
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line_of_error(e: WaypointError) -> u64 {
        match e {
            WaypointError::Line { line, .. } => line,
            other => panic!("not a line error: {other}"),
        }
    }

    #[test]
    fn csv_waypoints_parse_with_or_without_a_header_and_with_comments() {
        let plain = parse_csv("0,0\n2,0\n2,1.5\n").unwrap();
        assert_eq!(plain[2], Point::new(2.0, 1.5));
        let headed = parse_csv("# my path\nx, y\n0, 0\n\n 1.5 , -2 # comment-free line\n");
        // A comment character in the middle of a line is not a comment in CSV: an error.
        assert!(headed.is_err());
        let headed = parse_csv("# my path\nx, y\n0, 0\n\n 1.5 , -2\n").unwrap();
        assert_eq!(headed, vec![Point::new(0.0, 0.0), Point::new(1.5, -2.0)]);
        let reordered = parse_csv("t,y,x\n0,1,2\n1,3,4\n").unwrap();
        assert_eq!(reordered, vec![Point::new(2.0, 1.0), Point::new(4.0, 3.0)]);
    }

    #[test]
    fn csv_errors_name_the_line() {
        let e = parse_csv("x,y\n0,0\n1,abc\n").unwrap_err();
        assert!(e.to_string().contains("line 3"), "{e}");
        assert!(e.to_string().contains("'abc' is not a number"), "{e}");
        assert_eq!(line_of_error(parse_csv("0,0\n1\n").unwrap_err()), 2);
        assert_eq!(line_of_error(parse_csv("0,0\n1,2,3\n").unwrap_err()), 2);
        assert_eq!(line_of_error(parse_csv("0,0\n\n\n1,inf\n").unwrap_err()), 4);
        assert_eq!(line_of_error(parse_csv("a,b\n0,0\n").unwrap_err()), 1);
        assert_eq!(
            line_of_error(parse_csv("# comment\n\n0,0\n# another\n\n1,x\n").unwrap_err()),
            6
        );
        assert!(matches!(
            parse_csv("x,y\n1,1\n").unwrap_err(),
            WaypointError::TooFew(1)
        ));
    }

    #[test]
    fn toml_waypoints_parse_integers_and_floats() {
        let points =
            parse_toml("[[waypoint]]\nx = 0\ny = 0\n\n[[waypoint]]\nx = 2.5\ny = -1\n").unwrap();
        assert_eq!(points, vec![Point::new(0.0, 0.0), Point::new(2.5, -1.0)]);
    }

    #[test]
    fn toml_errors_name_the_line() {
        let missing =
            parse_toml("[[waypoint]]\nx = 0\ny = 0\n\n[[waypoint]]\nx = 1\n").unwrap_err();
        assert_eq!(line_of_error(missing), 5);
        let typo =
            parse_toml("[[waypoint]]\nx = 0\ny = 0\n[[waypoint]]\nx = 1\nz = 2\n").unwrap_err();
        assert!(typo.to_string().contains("line 6"), "{typo}");
        let text =
            parse_toml("[[waypoint]]\nx = 0\ny = 0\n[[waypoint]]\nx = 'one'\ny = 0\n").unwrap_err();
        assert!(text.to_string().contains("line 5"), "{text}");
        let nan =
            parse_toml("[[waypoint]]\nx = 0\ny = 0\n[[waypoint]]\nx = nan\ny = 0\n").unwrap_err();
        assert_eq!(line_of_error(nan), 4);
        assert!(matches!(
            parse_toml("").unwrap_err(),
            WaypointError::TooFew(0)
        ));
    }
}
