//! chassis-teleop.

fn main() {}
