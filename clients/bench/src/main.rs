//! chassis-bench.

fn main() {}
