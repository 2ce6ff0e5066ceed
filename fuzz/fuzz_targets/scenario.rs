//! The scenario parser and validator: what `sdem check` and `sdem run` do with a scenario file
//! before the run starts (`Scenario::load` without the sample and shape files, which have
//! their own targets), and the derived settings `sdem check` prints.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sdem::scenario::{Model, Scenario};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(mut scenario) = Scenario::parse(text, "fuzz.ron") else {
        return;
    };
    if scenario.sample.file.is_some() {
        // `Scenario::load` checks the settings the packing check needs, then reads the file:
        // here a folder that does not exist, so the read fails with an I/O error.
        let _ = scenario.load_sample(std::path::Path::new("/nonexistent/sdem-fuzz"));
    }
    scenario.sample.loaded = None;
    if scenario.validate().is_err() {
        return;
    }
    // What `sdem check` prints of a valid scenario.
    let _ = scenario.time_step_value();
    let _ = scenario.parameters();
    let _ = scenario.interaction_range();
    let _ = scenario.tangential_ratio();
    let _ = scenario.friction();
    let _ = scenario.walls();
    if !matches!(scenario.model, Model::Meshfree(_)) {
        let _ = scenario.critical_time_step();
        let _ = scenario.rigid_critical_time_step();
    }
});
