//! The Zenoh session configuration of either side, as `chassis-zenoh` opens it: shared with
//! `chassis-bench`, whose bare Zenoh hop runs on sessions configured as the bridge's.

pub mod net;
