//! The checkpoint reader of `sdem resume` (`AnyCheckpoint::from_bytes`: header, checksum,
//! payload of either format version and either solver), on the raw input and on the input's
//! payload re-framed with a valid header (so that mutations reach the decoder behind the
//! checksum).
#![no_main]

use libfuzzer_sys::fuzz_target;
use sdem::run::checkpoint::{AnyCheckpoint, crc32};

const HEADER: usize = 24;

fn decode(bytes: &[u8]) {
    if let Ok(c) = AnyCheckpoint::from_bytes(bytes, "fuzz.bin") {
        // What `sdem resume` asks of it before resuming.
        let _ = (c.step(), c.time(), c.checkpoint_interval());
        let _ = c.scenario().validate();
    }
}

fuzz_target!(|data: &[u8]| {
    decode(data);
    if data.len() >= HEADER {
        let payload = &data[HEADER..];
        let mut framed = data[..HEADER].to_vec();
        framed[12..20].copy_from_slice(&(payload.len() as u64).to_le_bytes());
        framed[20..24].copy_from_slice(&crc32(payload).to_le_bytes());
        framed.extend_from_slice(payload);
        decode(&framed);
    }
});
