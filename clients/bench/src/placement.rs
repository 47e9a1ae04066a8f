//! Where the two ends of a measurement run: the same CPU or two CPUs. On a virtual machine a
//! wake-up across CPUs costs tens of microseconds and one on the same CPU a few, so every figure
//! is reported with its placement and compared only with a baseline of the same placement.
//! Also the scheduling and the clock the measurements run on.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use anyhow::bail;
use chassis_client::now_ns;
use nix::sys::time::TimeSpec;
use nix::time::{ClockId, ClockNanosleepFlags, clock_nanosleep};
use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Placement {
    /// Both ends pinned to CPU 0.
    SameCpu,
    /// The service (or the pong side) on CPU 0, the client on CPU 1.
    CrossCpu,
}

impl Placement {
    pub fn label(self) -> &'static str {
        match self {
            Placement::SameCpu => "same CPU",
            Placement::CrossCpu => "cross CPU",
        }
    }

    /// (client / ping side, service / pong side).
    pub fn cpus(self) -> (Option<usize>, Option<usize>) {
        match self {
            Placement::SameCpu => (Some(0), Some(0)),
            Placement::CrossCpu => (Some(1), Some(0)),
        }
    }
}

pub fn pin_current_thread(cpu: usize) -> anyhow::Result<()> {
    if !core_affinity::set_for_current(core_affinity::CoreId { id: cpu }) {
        bail!("cannot pin to CPU {cpu}");
    }
    Ok(())
}

/// Lets the calling thread run on every CPU again.
pub fn unpin_current_thread() {
    let mut set = nix::sched::CpuSet::new();
    for core in core_affinity::get_core_ids().unwrap_or_default() {
        let _ = set.set(core.id);
    }
    let _ = nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), &set);
}

/// The calling thread at SCHED_FIFO `priority`, its memory not locked.
pub fn set_fifo(priority: u8) -> anyhow::Result<()> {
    let param = libc::sched_param {
        sched_priority: i32::from(priority),
    };
    // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param for the call.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
        let error = std::io::Error::last_os_error();
        bail!("SCHED_FIFO {priority} refused: {error}");
    }
    Ok(())
}

/// The calling thread at SCHED_FIFO `priority` and every page of the process locked, as
/// chassisd's real-time mode does (`--realtime`): a baseline's receiver living as the service's
/// loop did. Unlike chassisd, a refusal is an error: the bench asks for it only beside a
/// chassisd that was granted it.
pub fn enter_realtime(priority: u8) -> anyhow::Result<()> {
    set_fifo(priority)?;
    // SAFETY: mlockall takes flags only.
    if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
        let error = std::io::Error::last_os_error();
        bail!("locking memory refused: {error}");
    }
    Ok(())
}

/// Number of CPUs online. Not `available_parallelism`: that counts the CPUs the calling thread
/// may use, one while it is pinned.
pub fn cpu_count() -> usize {
    // SAFETY: sysconf takes a name and reads nothing else.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    usize::try_from(n).map_or(1, |n| n.max(1))
}

/// A number unique within this process.
pub fn unique() -> u64 {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    COUNTER.fetch_add(1, Ordering::Relaxed)
}

/// A small stable hash (FNV-1a) of `text`.
pub fn hash(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// `d` in ns, saturating far beyond any wait of the bench.
pub fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX / 2)
}

/// Sleeps on `CLOCK_MONOTONIC` for `d`, or until `d` with `TIMER_ABSTIME`.
fn sleep(d: Duration, flags: ClockNanosleepFlags) {
    let _ = clock_nanosleep(ClockId::CLOCK_MONOTONIC, flags, &TimeSpec::from_duration(d));
}

/// Waits `d` (the benchmark's orchestration between measurements; never inside one).
pub fn pause(d: Duration) {
    sleep(d, ClockNanosleepFlags::empty());
}

/// A periodic loop on absolute deadlines, as a controller's: period `k` starts at
/// `start + k·period`; a late period runs at once (none is skipped), and a period whose work ends
/// after the next one was due is a deadline miss.
pub struct Periods {
    next: u64,
    period: u64,
    /// The counted periods that ended late.
    pub misses: u64,
}

impl Periods {
    pub fn new(period: Duration) -> Self {
        let period = nanos(period).max(1);
        let next = now_ns() + period;
        Self {
            next,
            period,
            misses: 0,
        }
    }

    /// Sleeps until the next period is due; returns when it was due.
    pub fn next(&mut self) -> u64 {
        let due = self.next;
        sleep(
            Duration::from_nanos(due),
            ClockNanosleepFlags::TIMER_ABSTIME,
        );
        self.next += self.period;
        due
    }

    /// Ends the period due at `due`: a miss, if `counted`, when it ends after the next one was
    /// due.
    pub fn end(&mut self, due: u64, counted: bool) {
        if counted && now_ns() > due + self.period {
            self.misses += 1;
        }
    }
}
