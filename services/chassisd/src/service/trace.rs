//! The pass trace, for `chassis-bench`'s table of where each microsecond goes: with
//! `CHASSIS_PASS_TRACE=FILE` in its environment, the shell keeps the stamps it takes inside each
//! pass that wrote a frame or published a state, in memory (at most [`MAX_PASSES`], the first
//! ones), and writes them to FILE as the service stops. Without the variable nothing is kept and
//! no stamp is taken beyond the ones the service takes anyway.
//!
//! FILE: a header line naming the columns, then one line per pass, `CLOCK_MONOTONIC` ns, 0 where
//! the pass did not do the thing: `waited_since` (the loop began waiting for the wake-up that
//! started this pass, its previous passes' work done; a polling loop polls again), `woke` (the
//! engine's first clock reading of the pass: the mux decision's `stamp_ns`), `requests_read` (the
//! read of the sources that took a request returned), `write_started` and `written` (the pass's
//! first write to the bus began; its frame was out: the write returned, or the flush that carried a
//! held frame did — the frame tap's TX stamp), `state_handed` (the first state sample loaned: its
//! `published_ns`), `state_sent` (its send returned), `state_wake_begun` and `state_readers_woken`
//! (the state readers' notification began, once the pass's other work was done; it returned).

use std::path::PathBuf;

pub(crate) use chassis_ipc::PassStamps;
use chassis_ipc::Trace;

/// Most passes kept (9 stamps each: about 14 MB).
pub(crate) const MAX_PASSES: usize = 200_000;

/// The passes kept and the one under way.
#[derive(Debug)]
pub(crate) struct PassTrace {
    path: PathBuf,
    passes: Vec<PassStamps>,
    /// The pass under way.
    pub current: PassStamps,
    /// When the loop last began waiting for a wake-up (the next pass's `waited_since`).
    pub waiting_since: u64,
}

impl PassTrace {
    /// The trace `CHASSIS_PASS_TRACE` asks for, if it does and this build keeps traces
    /// ([`Trace::file`]).
    pub fn from_env() -> Option<Self> {
        Some(Self {
            path: Trace::Pass.file()?,
            passes: Vec::with_capacity(MAX_PASSES),
            current: PassStamps::default(),
            waiting_since: 0,
        })
    }

    /// Ends the pass under way: kept when it wrote or published a state.
    pub fn end_pass(&mut self) {
        let pass = std::mem::take(&mut self.current);
        if (pass.written != 0 || pass.state_handed != 0) && self.passes.len() < MAX_PASSES {
            self.passes.push(pass);
        }
    }

    /// Writes the passes kept to the file.
    pub fn write_out(&self) -> std::io::Result<()> {
        PassStamps::write_trace(&self.path, &self.passes)
    }

    pub fn path(&self) -> &std::path::Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_passes_that_wrote_or_published_are_kept_and_a_stamp_is_the_first_of_its_pass() {
        let dir = std::env::temp_dir().join(format!("pass-trace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut trace = PassTrace {
            path: dir.join("passes.txt"),
            passes: Vec::new(),
            current: PassStamps::default(),
            waiting_since: 0,
        };
        PassStamps::first(&mut trace.current.woke, 10);
        trace.end_pass();
        PassStamps::first(&mut trace.current.woke, 20);
        PassStamps::first(&mut trace.current.written, 25);
        PassStamps::first(&mut trace.current.written, 27);
        trace.end_pass();
        trace.write_out().unwrap();
        if Trace::ENABLED {
            let text = std::fs::read_to_string(trace.path()).unwrap();
            assert_eq!(
                text,
                format!("{}\n0 20 0 0 25 0 0 0 0\n", PassStamps::HEADER)
            );
        } else {
            // `cargo test -p chassisd` alone: chassis-ipc without its `trace` feature.
            assert!(!trace.path().exists(), "a build without traces wrote one");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
