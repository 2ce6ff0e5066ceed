//! The sample-file (CSV) reader: `Scenario::load_sample`'s parse and packing check of the
//! grains against a shipped scenario's box, contact law and contour resolution.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sdem::sample::file::{check_packing, parse_grains};
use sdem::scenario::Scenario;
use std::sync::OnceLock;

fn scenario() -> &'static Scenario {
    static S: OnceLock<Scenario> = OnceLock::new();
    S.get_or_init(|| {
        Scenario::parse(
            include_str!("../../scenarios/compaction30_prepare.ron"),
            "compaction30_prepare.ron",
        )
        .expect("a shipped scenario parses")
    })
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(sample) = parse_grains(text, "fuzz.csv") else {
        return;
    };
    let s = scenario();
    let _ = check_packing(
        "fuzz.csv",
        &sample,
        s.sample.bounds(),
        &s.secant_law(),
        s.contact.resolution_deg,
    );
});
