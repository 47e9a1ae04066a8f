//! chassis-safety.

fn main() {}
