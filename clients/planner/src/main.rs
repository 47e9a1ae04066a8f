//! chassis-planner.

fn main() {}
