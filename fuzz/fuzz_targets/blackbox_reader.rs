//! Any bytes into the reader of chassisd's black box (`chassisd_blackbox::read`: a kept MCAP
//! window or the ring's JSON lines, what `chassis explain` opens): no panic; what it takes prints
//! back to one line per event that reads as the same event, and a window written of those lines
//! reads back to the same events.
#![no_main]

use std::io::Cursor;

use chassisd_blackbox::{Event, read, write_mcap};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(events) = read(data) else {
        return;
    };
    let mut text = Vec::new();
    for event in &events {
        let line = event.to_line().expect("an event prints as JSON");
        assert!(!line.contains('\n'), "{line}");
        assert_eq!(&Event::from_line(&line).expect("its line reads back"), event);
        text.extend_from_slice(line.as_bytes());
        text.push(b'\n');
    }
    if events.is_empty() {
        return;
    }
    let mut window = Cursor::new(Vec::new());
    write_mcap(&mut window, &text, "fuzz").expect("a window of what was read");
    assert_eq!(read(window.get_ref()).expect("the window reads back"), events);
});
