//! The loop's thread and the simulated chassis' thread on the machine: pinning to CPUs and
//! real-time scheduling (SCHED_FIFO, locked memory), and what the kernel's real-time throttling
//! does to a polling loop.

use std::time::Duration;

use chassisd_config::Config;

/// Why the loop's thread could not be pinned.
#[derive(Debug, thiserror::Error)]
#[error("pinning the loop to CPU {cpu}: {source}")]
pub struct PinError {
    pub cpu: usize,
    #[source]
    pub source: nix::Error,
}

/// The CPUs of the embedded simulated chassis' thread (all when empty), for a loop that runs at
/// SCHED_FIFO or not (`fifo`). A loop left unpinned leaves it unpinned. A pinned loop that
/// blocks at SCHED_FIFO shares its CPU with it: the chassis runs only while the loop waits, and
/// the loop's write to it wakes no other CPU (a wake-up of an idle CPU costs the write tens of
/// microseconds on a virtual machine), as a write to a CAN controller wakes none. Any other
/// pinned loop leaves it the other CPUs: at normal scheduling the chassis would preempt the loop,
/// and a polling loop would starve it.
pub fn sim_cpus(config: &Config, fifo: bool) -> Vec<usize> {
    let Some(cpu) = config.cpu else {
        return Vec::new();
    };
    if fifo && config.loop_mode != chassisd_config::LoopMode::Spin {
        return vec![cpu];
    }
    (0..online_cpus()).filter(|&c| c != cpu).collect()
}

/// The CPUs the machine has online. Not `available_parallelism`: that counts the CPUs the calling
/// thread may use, one once the loop's thread is pinned.
pub fn online_cpus() -> usize {
    // SAFETY: sysconf takes a name and reads nothing else.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    usize::try_from(n).map_or(1, |n| n.max(1))
}

/// Pins the calling thread to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> Result<(), PinError> {
    confine(nix::unistd::Pid::from_raw(0), &[cpu]).map_err(|source| PinError { cpu, source })
}

/// Confines the thread `tid` (0: the calling one) to `cpus`, every online CPU when empty.
pub fn confine(tid: nix::unistd::Pid, cpus: &[usize]) -> Result<(), nix::Error> {
    let mut set = nix::sched::CpuSet::new();
    if cpus.is_empty() {
        for cpu in 0..online_cpus() {
            set.set(cpu)?;
        }
    }
    for &cpu in cpus {
        set.set(cpu)?;
    }
    nix::sched::sched_setaffinity(tid, &set)
}

/// What real-time mode got from the system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Realtime {
    /// The loop's thread runs at SCHED_FIFO.
    pub fifo: bool,
    /// Every page of the process is locked in memory.
    pub locked: bool,
}

/// Why the system refused a part of real-time mode.
#[derive(Debug, thiserror::Error)]
pub enum RealtimeError {
    #[error(
        "SCHED_FIFO priority {priority} refused: {source} (needs CAP_SYS_NICE or an \
         RLIMIT_RTPRIO of at least {priority}: `LimitRTPRIO=` in the unit, or rtprio in \
         /etc/security/limits.conf)"
    )]
    Fifo {
        priority: u8,
        source: std::io::Error,
    },
    #[error(
        "locking memory refused: {0} (needs CAP_IPC_LOCK or `LimitMEMLOCK=infinity` in the unit)"
    )]
    Lock(std::io::Error),
}

/// Real-time mode for the calling thread: SCHED_FIFO at `priority`, then every page of the
/// process locked (current and future). Each refusal is returned beside what was granted; the
/// caller warns and carries on with normal scheduling.
pub fn enter_realtime(priority: u8) -> (Realtime, Vec<RealtimeError>) {
    let mut errors = Vec::new();
    let param = libc::sched_param {
        sched_priority: i32::from(priority),
    };
    // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param for the call.
    let fifo = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } == 0;
    if !fifo {
        errors.push(RealtimeError::Fifo {
            priority,
            source: std::io::Error::last_os_error(),
        });
    }
    // SAFETY: mlockall takes flags only.
    let locked = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0;
    if !locked {
        errors.push(RealtimeError::Lock(std::io::Error::last_os_error()));
    }
    (Realtime { fifo, locked }, errors)
}

/// The kernel's throttling of real-time threads, from the texts of
/// `/proc/sys/kernel/sched_rt_runtime_us` and `sched_rt_period_us`: how long SCHED_FIFO threads
/// are stopped in each period once they used their share, and the period. None when the kernel
/// does not throttle them (`-1`, or the whole period) or the texts are not numbers.
pub fn rt_throttle(runtime_us: &str, period_us: &str) -> Option<(Duration, Duration)> {
    let runtime: i64 = runtime_us.trim().parse().ok()?;
    let period: u64 = period_us.trim().parse().ok()?;
    let runtime = u64::try_from(runtime).ok()?;
    (runtime < period).then(|| {
        (
            Duration::from_micros(period - runtime),
            Duration::from_micros(period),
        )
    })
}

/// The warning for a polling loop in real-time mode on a kernel that throttles real-time
/// threads: the loop never blocks, so it uses its share of every period and is stopped for the
/// rest of it, motion frames and the heartbeat included.
pub fn spin_throttle_warning(runtime_us: &str, period_us: &str) -> Option<String> {
    let (stopped, period) = rt_throttle(runtime_us, period_us)?;
    Some(format!(
        "--realtime with the spin loop: the kernel lets SCHED_FIFO threads run {} of every {} \
         (kernel.sched_rt_runtime_us), so the loop, which never blocks, stops for {stopped:?} of \
         every {period:?}; give it an isolated CPU (isolcpus=, --cpu) and set \
         kernel.sched_rt_runtime_us = -1, or use the event or hybrid loop",
        runtime_us.trim(),
        period_us.trim()
    ))
}

/// The calling thread's scheduling policy is SCHED_FIFO.
pub fn is_fifo() -> bool {
    // SAFETY: pid 0 is the calling thread.
    unsafe { libc::sched_getscheduler(0) == libc::SCHED_FIFO }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassisd_config::{LoopMode, Overrides, RawConfig};

    /// The kernel's default (950 ms of every second) stops a polling real-time loop for 50 ms a
    /// second; no throttling, or a share of the whole period, stops it never.
    #[test]
    fn a_throttled_kernel_is_named_for_the_spin_loop_in_realtime_mode() {
        assert_eq!(
            rt_throttle("950000\n", "1000000\n"),
            Some((Duration::from_millis(50), Duration::from_secs(1)))
        );
        let warning = spin_throttle_warning("950000\n", "1000000\n").unwrap_or_default();
        assert!(warning.contains("stops for 50ms of every 1s"), "{warning}");
        assert_eq!(rt_throttle("-1\n", "1000000\n"), None);
        assert_eq!(rt_throttle("1000000", "1000000"), None);
        assert_eq!(rt_throttle("", "1000000"), None);
        assert_eq!(spin_throttle_warning("-1", "1000000"), None);
    }

    /// The simulated chassis shares a pinned loop's CPU only while the loop blocks at
    /// SCHED_FIFO; any other pinned loop leaves it the other CPUs, an unpinned one every CPU.
    #[test]
    fn the_simulated_chassis_shares_the_cpu_of_a_pinned_real_time_loop_that_blocks() {
        let config = |cpu: Option<usize>, loop_mode: LoopMode| {
            let raw: RawConfig = toml::from_str("[service]\nrobot = \"titan\"\n").unwrap();
            raw.validate(Overrides {
                cpu,
                loop_mode: Some(loop_mode),
                ..Overrides::default()
            })
            .unwrap()
        };
        let others: Vec<usize> = (1..online_cpus()).collect();
        for fifo in [false, true] {
            assert!(sim_cpus(&config(None, LoopMode::Event), fifo).is_empty());
            assert_eq!(sim_cpus(&config(Some(0), LoopMode::Spin), fifo), others);
        }
        for mode in [LoopMode::Event, LoopMode::Hybrid] {
            assert_eq!(sim_cpus(&config(Some(0), mode), true), vec![0]);
            assert_eq!(sim_cpus(&config(Some(0), mode), false), others);
        }
    }
}
