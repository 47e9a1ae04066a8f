//! `chassis-ros2`: a robot served by chassisd, as a ROS 2 base driver, in pure Rust.
//!
//! The bridge speaks DDS itself through [`ros2_client`] (on RustDDS): no ROS installation, no
//! colcon, only cargo. It was chosen over the alternatives because it is pure Rust and
//! maintained (releases follow the ROS 2 distributions; Jazzy is the default), it implements
//! ROS 2's naming, type names and both service mappings of the RMW layers (Fast DDS' "enhanced"
//! and Cyclone DDS'), and it needs no C toolchain; `r2r` and `rclrs` need a sourced ROS 2
//! installation to build, and the `cyclonedds` bindings a C library.
//!
//! [`bridge`] holds the node and its loops, [`convert`] the state → message mapping (pure
//! functions), [`msg`] the ROS 2 message types, [`discovery`] how far the participant reaches
//! (ROS 2's discovery switches; this computer only by default).

pub mod bridge;
pub mod convert;
pub mod discovery;
pub mod msg;
pub mod record;
