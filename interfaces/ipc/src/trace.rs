//! chassisd's pass trace (`CHASSIS_PASS_TRACE=FILE`, [`crate::PASS_TRACE_ENV`]): the stamps the
//! service takes inside each pass, written by chassisd as it stops and read by `chassis-bench`
//! to split its rows. One format, here, for the writer and the reader.
//!
//! FILE: [`PassStamps::HEADER`], then one [`PassStamps::line`] per pass, `CLOCK_MONOTONIC` ns,
//! 0 where the pass did not do the thing.

use thiserror::Error;

/// The stamps of one pass, ns (0: not taken).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PassStamps {
    pub woke: u64,
    pub requests_read: u64,
    pub write_started: u64,
    pub written: u64,
    pub state_handed: u64,
    pub state_sent: u64,
    pub state_readers_woken: u64,
}

/// Why a pass trace cannot be read.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum TraceError {
    #[error("unknown columns '{0}'")]
    Columns(String),
    #[error("'{0}' is not 7 stamps")]
    Line(String),
}

impl PassStamps {
    /// The first line of a trace, naming the columns.
    pub const HEADER: &'static str =
        "woke requests_read write_started written state_handed state_sent state_readers_woken";

    /// The stamps in the trace's column order ([`PassStamps::HEADER`]).
    fn columns(&self) -> [u64; 7] {
        [
            self.woke,
            self.requests_read,
            self.write_started,
            self.written,
            self.state_handed,
            self.state_sent,
            self.state_readers_woken,
        ]
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
        let mut lines = text.lines();
        let header = lines.next().unwrap_or_default();
        if header != Self::HEADER {
            return Err(TraceError::Columns(header.to_string()));
        }
        lines
            .map(|line| {
                let v: Vec<u64> = line
                    .split_whitespace()
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|_| TraceError::Line(line.to_string()))?;
                let [
                    woke,
                    requests_read,
                    write_started,
                    written,
                    state_handed,
                    state_sent,
                    state_readers_woken,
                ] = <[u64; 7]>::try_from(v).map_err(|_| TraceError::Line(line.to_string()))?;
                Ok(Self {
                    woke,
                    requests_read,
                    write_started,
                    written,
                    state_handed,
                    state_sent,
                    state_readers_woken,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trace_reads_back_as_written() {
        let pass = PassStamps {
            woke: 1,
            requests_read: 2,
            write_started: 3,
            written: 4,
            state_handed: 0,
            state_sent: 6,
            state_readers_woken: 7,
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
}
