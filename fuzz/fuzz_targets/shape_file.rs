//! The shape-file reader (`sample.shapes: File(...)` of a meshfree scenario): parse, then the
//! scenario's validation of the grains it gives (count, box), as `Scenario::load` does.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sdem::meshfree::shape::parse_shapes;
use sdem::scenario::{GrainShapes, LoadedShapes, Scenario};
use std::sync::{Arc, OnceLock};

fn scenario() -> &'static Scenario {
    static S: OnceLock<Scenario> = OnceLock::new();
    S.get_or_init(|| {
        let mut s = Scenario::parse(
            include_str!("../../scenarios/meshfree_bouncing_disc.ron"),
            "meshfree_bouncing_disc.ron",
        )
        .expect("a shipped scenario parses");
        s.sample.file = None;
        s.sample.shapes = Some(GrainShapes::File("fuzz.txt".into()));
        s
    })
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(grains) = parse_shapes(text, "fuzz.txt") else {
        return;
    };
    let mut s = scenario().clone();
    s.sample.loaded_shapes = Some(Arc::new(LoadedShapes {
        path: "fuzz.txt".into(),
        grains,
    }));
    let _ = s.validate();
});
