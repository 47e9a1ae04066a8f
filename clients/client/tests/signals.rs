//! SIGINT/SIGTERM end a client's loops however other signals follow. systemd stops a service
//! with SIGTERM and a SIGCONT at once; iceoryx2 keeps only the last signal of any kind, so a
//! termination read from there was lost and `systemctl stop` waited for its timeout. (A process
//! of its own: the flag, once set, stays set.)

use chassis_client::{install_signal_handlers, termination_requested};
use nix::sys::signal::{Signal, raise};

#[test]
fn a_sigterm_followed_by_a_sigcont_and_a_sigusr1_is_a_termination() {
    install_signal_handlers();
    raise(Signal::SIGCONT).unwrap();
    assert!(
        !termination_requested(),
        "a SIGCONT alone is no termination"
    );
    for signal in [Signal::SIGTERM, Signal::SIGCONT, Signal::SIGUSR1] {
        raise(signal).unwrap();
    }
    assert!(termination_requested());
    assert!(termination_requested(), "it stays requested");
}
