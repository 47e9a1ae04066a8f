//! `chassisd`: the chassis hardware service.

fn main() {}
