//! `chassis-foxglove`'s library: what a robot looks like in Foxglove ([`view`]), shared by the
//! live bridge (the `chassis-foxglove` binary) and `chassis record`, so a recording replayed in
//! Foxglove shows the same frames, pose, fix and log as the live view.

pub mod view;
