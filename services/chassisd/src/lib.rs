//! chassisd: the hardware service of one robot.
//!
//! One process owns the robot's bus and is the only way to its motors. It decodes every frame
//! into a fixed-layout [`chassis_interfaces::ChassisState`] published over iceoryx2 shared
//! memory, and it drives the chassis from a priority mux over the velocity requests of the
//! configured sources.

pub mod blackbox;
pub mod description;
pub mod engine;
pub mod ipc;
pub mod lockfile;
pub mod mux;
pub mod notify;
pub mod realtime;
pub mod rx_moderation;
pub mod service;
pub mod setup;
pub mod sim;
pub mod sim_process;
