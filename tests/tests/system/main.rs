//! Every multi-process test of the robot but the fault matrix (`tests/tests/faults_*.rs`, which
//! keeps its own binaries for its machine lock) and the tests that need a VM or ten minutes
//! (`vcan.rs`, `sja1000.rs`, `soak.rs`): one test binary, one module per subject, so cargo links
//! it once and its four test threads (`RUST_TEST_THREADS` in scripts/test) run across subjects
//! instead of waiting on each file's slowest test. `cargo test -p chassis-tests --test system
//! planner::` runs one subject.

mod bench;
mod blackbox;
mod demo;
mod description;
mod doctor;
mod fleet;
mod host_programs;
mod imports;
mod latch;
mod layering;
mod manual;
mod planner;
mod protocol_v2;
mod record;
mod ros2_reach;
mod safety;
mod scripts;
mod serial;
mod service;
mod speed_limit;
mod systemd;
mod teleop;
mod zenoh;
