//! Stamp traces, read by `chassis-bench` to split its rows: chassisd's pass trace
//! (`CHASSIS_PASS_TRACE=FILE`, [`Trace::Pass`]), the stamps the service takes inside each pass,
//! written by chassisd as it stops, and the bridges' traces ([`StampTrace`]). One format, here,
//! for the writers and the reader. Only a build with the `trace` feature keeps them (the
//! workspace's, which the bench needs); without it [`Trace::file`] is never a file.
//!
//! FILE: a header naming the columns ([`PassStamps::HEADER`]), then one line per pass or item,
//! `CLOCK_MONOTONIC` ns, 0 where the pass did not do the thing.

use std::path::{Path, PathBuf};

use thiserror::Error;

/// The stamps of one pass, ns (0: not taken).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PassStamps {
    /// The loop began waiting for this pass's wake-up: its previous passes' work was done.
    pub waited_since: u64,
    pub woke: u64,
    pub requests_read: u64,
    pub write_started: u64,
    pub written: u64,
    pub state_handed: u64,
    pub state_sent: u64,
    /// The state readers' notification began (the pass's other work done).
    pub state_wake_begun: u64,
    pub state_readers_woken: u64,
}

/// Why a pass trace cannot be read.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum TraceError {
    #[error("unknown columns '{0}'")]
    Columns(String),
    #[error("'{0}' is not as many stamps as the header names")]
    Line(String),
}

/// Which stamp trace: chassisd's pass trace and the bridges' (their file formats, and the
/// environment variable naming each one's file).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trace {
    /// chassisd's passes ([`PassStamps`]).
    Pass,
    /// The ROS 2 bridge's odoms: the frame read (the state's `stamp_ns`), the state loop woken
    /// with the sample, the odom handed to RustDDS and the write returned.
    Odom,
    /// chassis-zenoh's robot side: for each state it puts, the frame read, the export loop woken
    /// with the sample, the put begun and the put returned.
    ZenohExport,
    /// chassis-zenoh's operator side (`--mirror`): for each state it takes from the robot, the
    /// frame read, the sample in the Zenoh subscriber's callback, taken by the mirror's loop, and
    /// handed to iceoryx2.
    ZenohMirror,
}

impl Trace {
    /// This build keeps traces (the `trace` feature).
    pub const ENABLED: bool = cfg!(feature = "trace");

    /// The environment variable naming the trace's file (this build keeps traces: the `trace`
    /// feature).
    #[cfg(feature = "trace")]
    pub const fn env(self) -> &'static str {
        match self {
            Trace::Pass => "CHASSIS_PASS_TRACE",
            Trace::Odom => "CHASSIS_ROS2_TRACE",
            Trace::ZenohExport | Trace::ZenohMirror => "CHASSIS_ZENOH_TRACE",
        }
    }

    /// The first line of the trace, naming its columns.
    pub const fn header(self) -> &'static str {
        match self {
            Trace::Pass => PassStamps::HEADER,
            Trace::Odom => "read_ns woke_ns write_begun_ns written_ns",
            Trace::ZenohExport => "read_ns woke_ns put_begun_ns put_returned_ns",
            Trace::ZenohMirror => "read_ns received_ns taken_ns handed_ns",
        }
    }

    /// The file the environment asks this trace to be written to; never one in a build without
    /// the `trace` feature.
    pub fn file(self) -> Option<PathBuf> {
        #[cfg(feature = "trace")]
        return std::env::var_os(self.env()).map(PathBuf::from);
        #[cfg(not(feature = "trace"))]
        None
    }
}

/// A bridge's trace: `N` stamps for each item its loop handles (an odom it publishes, a state it
/// puts or takes), kept in memory while it runs and written as it stops. `chassis-bench` joins
/// the traces on their first column, the read time of the frame the item carries.
#[derive(Debug)]
pub struct StampTrace<const N: usize> {
    path: PathBuf,
    header: &'static str,
    lines: Vec<[u64; N]>,
}

impl<const N: usize> StampTrace<N> {
    /// A trace to the file the environment names for `trace`, if it names one
    /// ([`Trace::file`]).
    pub fn from_env(trace: Trace) -> Option<Self> {
        Some(Self {
            path: trace.file()?,
            header: trace.header(),
            lines: Vec::with_capacity(1 << 16),
        })
    }

    /// Keeps one item's stamps.
    pub fn push(&mut self, stamps: [u64; N]) {
        self.lines.push(stamps);
    }

    /// Where the trace is written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The header and every item kept, one a line.
    pub fn text(&self) -> String {
        let mut text = format!("{}\n", self.header);
        for stamps in &self.lines {
            text.push_str(&stamps.map(|s| s.to_string()).join(" "));
            text.push('\n');
        }
        text
    }

    /// The items of a trace of `trace`.
    pub fn parse(text: &str, trace: Trace) -> Result<Vec<[u64; N]>, TraceError> {
        Self::parse_as(text, trace.header())
    }

    /// Writes the trace to its file.
    pub fn write(&self) -> std::io::Result<()> {
        std::fs::write(&self.path, self.text())
    }

    /// The items of a trace whose first line is `header`.
    pub fn parse_as(text: &str, header: &str) -> Result<Vec<[u64; N]>, TraceError> {
        let mut lines = text.lines();
        let first = lines.next().unwrap_or_default();
        if first != header {
            return Err(TraceError::Columns(first.to_string()));
        }
        lines
            .map(|line| {
                let v: Vec<u64> = line
                    .split_whitespace()
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|_| TraceError::Line(line.to_string()))?;
                <[u64; N]>::try_from(v).map_err(|_| TraceError::Line(line.to_string()))
            })
            .collect()
    }
}

impl PassStamps {
    /// The first line of a trace, naming the columns.
    pub const HEADER: &'static str = "waited_since woke requests_read write_started written state_handed state_sent \
         state_wake_begun state_readers_woken";

    /// The stamps in the trace's column order ([`PassStamps::HEADER`]).
    fn columns(&self) -> [u64; 9] {
        [
            self.waited_since,
            self.woke,
            self.requests_read,
            self.write_started,
            self.written,
            self.state_handed,
            self.state_sent,
            self.state_wake_begun,
            self.state_readers_woken,
        ]
    }

    /// Writes `passes` as a trace to `path`; a build without the `trace` feature writes nothing
    /// (and holds neither the header nor the format).
    pub fn write_trace(path: &Path, passes: &[PassStamps]) -> std::io::Result<()> {
        #[cfg(feature = "trace")]
        {
            use std::io::Write as _;
            let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
            writeln!(out, "{}", Self::HEADER)?;
            for pass in passes {
                writeln!(out, "{}", pass.line())?;
            }
            out.flush()
        }
        #[cfg(not(feature = "trace"))]
        {
            let _ = (path, passes);
            Ok(())
        }
    }

    /// This pass as a line of the trace.
    pub fn line(&self) -> String {
        self.columns().map(|s| s.to_string()).join(" ")
    }

    /// Sets `slot` to `now` unless the pass already took it.
    pub fn first(slot: &mut u64, now: u64) {
        if *slot == 0 {
            *slot = now;
        }
    }

    /// The passes of a whole trace.
    pub fn parse(text: &str) -> Result<Vec<Self>, TraceError> {
        Ok(StampTrace::<9>::parse_as(text, Self::HEADER)?
            .into_iter()
            .map(|c| Self {
                waited_since: c[0],
                woke: c[1],
                requests_read: c[2],
                write_started: c[3],
                written: c[4],
                state_handed: c[5],
                state_sent: c[6],
                state_wake_begun: c[7],
                state_readers_woken: c[8],
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trace_reads_back_as_written() {
        let pass = PassStamps {
            waited_since: 9,
            woke: 1,
            requests_read: 2,
            write_started: 3,
            written: 4,
            state_handed: 0,
            state_sent: 6,
            state_wake_begun: 7,
            state_readers_woken: 8,
        };
        let text = format!("{}\n{}\n", PassStamps::HEADER, pass.line());
        assert_eq!(PassStamps::parse(&text), Ok(vec![pass]));
        assert!(matches!(
            PassStamps::parse("woke\n1\n"),
            Err(TraceError::Columns(_))
        ));
        assert_eq!(
            PassStamps::parse(&format!("{}\n1 2 3\n", PassStamps::HEADER)),
            Err(TraceError::Line("1 2 3".into()))
        );
    }

    #[test]
    fn a_bridge_trace_reads_back_as_written() {
        let mut trace = StampTrace::<3> {
            path: PathBuf::new(),
            header: "a b c",
            lines: Vec::new(),
        };
        trace.push([1, 2, 3]);
        trace.push([4, 0, 6]);
        let text = trace.text();
        assert_eq!(text, "a b c\n1 2 3\n4 0 6\n");
        assert_eq!(
            StampTrace::<3>::parse_as(&text, "a b c"),
            Ok(vec![[1, 2, 3], [4, 0, 6]])
        );
        assert!(matches!(
            StampTrace::<3>::parse_as(&text, "a b"),
            Err(TraceError::Columns(_))
        ));
        assert_eq!(
            StampTrace::<3>::parse_as("a b c\n1 2\n", "a b c"),
            Err(TraceError::Line("1 2".into()))
        );
    }
}
