//! `cargo fuzz run decode` (from libs/servo_protocol): arbitrary bytes, fed in arbitrary
//! chunks, never panic the decoder, always make progress, and every frame it accepts
//! re-encodes to exactly the bytes it came from; the device model never panics either.
#![no_main]

use libfuzzer_sys::fuzz_target;
use servo_protocol::device::{Device, DeviceConfig};
use servo_protocol::{decode, encode};
use std::time::Duration;

fuzz_target!(|data: &[u8]| {
    let split = data.first().map(|b| usize::from(*b) + 1).unwrap_or(1);
    let mut buf = Vec::new();
    let mut device = Device::new(DeviceConfig::default());
    for (i, chunk) in data.chunks(split).enumerate() {
        buf.extend_from_slice(chunk);
        device.receive(chunk, Duration::from_millis(i as u64));
        let mut rounds = 0;
        loop {
            rounds += 1;
            assert!(rounds <= 4 * data.len() + 8, "decoder makes no progress");
            let before = buf.clone();
            match decode(&mut buf) {
                Ok(None) => break,
                Ok(Some(frame)) => {
                    let bytes = encode(&frame);
                    assert_eq!(&before[..bytes.len()], &bytes[..], "accepted frame does not re-encode to its bytes");
                }
                Err(_) => assert!(buf.len() < before.len(), "an error must drop bytes"),
            }
        }
        device.tick(Duration::from_millis(i as u64 + 1));
        let _ = device.take_output();
    }
});
