//! The same scenario gives the same bits on another machine: nothing in the simulation may
//! follow the processor's features. glibc's libm does (its `sin`, `cos` and `atan2` run an FMA
//! variant where the processor has FMA, which differs from the other in the last bit for some
//! arguments), so the simulation takes its sines, cosines and arc tangents from the `libm`
//! crate (`sdem::geometry::angle`). This test runs a small compaction of deforming grains
//! twice, the second time with glibc's FMA and AVX2 variants turned off
//! (`GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA`), as on a processor without them, and
//! compares the outputs byte for byte. With glibc's `sin_cos` in the grain shapes it failed
//! (macro.csv differed from line 40). Where the C library is not glibc, or the processor has no
//! FMA, the two runs take the same path and the test cannot tell.

mod common;

use common::{SMALL_COMPACTION, temp_dir};
use std::process::Command;

#[test]
fn a_run_does_not_depend_on_the_processors_floating_point_features() {
    let dir = temp_dir("machine", "fma");
    let scenario = dir.join("small.ron");
    std::fs::write(&scenario, SMALL_COMPACTION).unwrap();
    let run = |name: &str, tunables: Option<&str>| {
        let out = dir.join(name);
        let mut command = Command::new(env!("CARGO_BIN_EXE_sdem"));
        command
            .args(["run", "--quiet", "--out"])
            .arg(&out)
            .arg(&scenario);
        if let Some(tunables) = tunables {
            command.env("GLIBC_TUNABLES", tunables);
        }
        let status = command.output().unwrap();
        assert!(
            status.status.success(),
            "{}",
            String::from_utf8_lossy(&status.stderr)
        );
        out
    };
    let native = run("native", None);
    let without_fma = run("without_fma", Some("glibc.cpu.hwcaps=-AVX2,-FMA"));
    for file in ["macro.csv", "grains.csv"] {
        let (a, b) = (
            std::fs::read(native.join(file)).unwrap(),
            std::fs::read(without_fma.join(file)).unwrap(),
        );
        assert!(a.len() > 1000, "{file}: {} bytes", a.len());
        assert!(a == b, "{file} differs without FMA");
    }
}
