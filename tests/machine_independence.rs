//! The same scenario gives the same bits on another machine: nothing in the simulation may
//! follow the processor's features. glibc's libm does (its `sin`, `cos` and `atan2` run FMA
//! variants where the processor has FMA, which differ from the others in the last bit for some
//! arguments), so SDEM takes these functions from the `libm` crate (`sdem::geometry::angle`).
//! The test runs a scenario twice, the second time with glibc's FMA and AVX2 variants turned
//! off (`GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA`), as on a processor without them, and
//! compares the outputs byte for byte. With glibc's functions it failed: the compaction's
//! macro.csv differed from its line 40. Where the C library is not glibc, or the processor has
//! no FMA, the two runs take the same path and the test cannot tell. The meshfree solver takes
//! its exponentials, logarithms, powers and hypotenuses from portable code too (`sdem::portable`:
//! fdlibm ports, and `libm`'s `hypot`): with the platform's, `scenarios/meshfree_bouncing_disc.ron`
//! differed from macro.csv's line 3 this way. (Its sparse factorisations come from faer, which picks its SIMD kernels, FMA
//! included, from the processor at run time: a machine without AVX2 and FMA may still round
//! them differently, which turning glibc's variants off does not show.)

mod common;

use common::{SMALL_COMPACTION, temp_dir};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `scenario` into `dir/name` with the environment variable `var` set (none for `None`),
/// and returns that folder.
fn run_with(scenario: &Path, dir: &Path, name: &str, var: Option<(&str, &str)>) -> PathBuf {
    let out = dir.join(name);
    let mut command = Command::new(env!("CARGO_BIN_EXE_sdem"));
    command
        .args(["run", "--quiet", "--out"])
        .arg(&out)
        .arg(scenario);
    if let Some((key, value)) = var {
        command.env(key, value);
    }
    let status = command.output().unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    out
}

/// Asserts that the runs in folders `a` and `b` wrote the same macro.csv and grains.csv, with
/// rows below their headers; `what` names the difference between the runs.
fn assert_same_outputs(a: &Path, b: &Path, what: &str) {
    for file in ["macro.csv", "grains.csv"] {
        let (a, b) = (
            std::fs::read(a.join(file)).unwrap(),
            std::fs::read(b.join(file)).unwrap(),
        );
        let rows = a.iter().filter(|&&c| c == b'\n').count();
        assert!(rows >= 2, "{file}: {rows} lines, no row below the header");
        assert!(a == b, "{file} differs {what}");
    }
}

/// Runs `scenario` natively and without glibc's FMA variants, in `dir`, and asserts that both
/// runs wrote the same macro.csv and grains.csv.
fn assert_same_without_fma(scenario: &Path, dir: &Path) {
    let native = run_with(scenario, dir, "native", None);
    let tunables = ("GLIBC_TUNABLES", "glibc.cpu.hwcaps=-AVX2,-FMA");
    let without_fma = run_with(scenario, dir, "without_fma", Some(tunables));
    assert_same_outputs(&native, &without_fma, "without FMA");
}

#[test]
fn an_sdem_run_does_not_depend_on_the_processors_floating_point_features() {
    // 200 deforming grains compacted through jamming: shapes, contours and contacts.
    let dir = temp_dir("machine", "sdem");
    let scenario = dir.join("small.ron");
    std::fs::write(&scenario, SMALL_COMPACTION).unwrap();
    assert_same_without_fma(&scenario, &dir);
}

#[test]
fn a_meshfree_run_does_not_depend_on_the_processors_floating_point_features() {
    // One hyperelastic disc dropped on a wall (implicit, Bathe): RPIM shape functions
    // (exponentials), the neo-Hookean law (logarithms), node placement and contact.
    let dir = temp_dir("machine", "meshfree");
    let scenario =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/meshfree_bouncing_disc.ron");
    assert_same_without_fma(&scenario, &dir);
}

#[test]
fn an_sdem_run_gives_the_same_bits_in_avx_and_avx512_lanes() {
    // Expectation: the kernels compute the same operations in the same order whatever the
    // vector width (`sdem::lanes::Simd`), so SDEM_SIMD changes the speed, never the outputs.
    // Where the processor lacks AVX-512 both runs take AVX and the test cannot tell.
    let dir = temp_dir("machine", "simd");
    let scenario = dir.join("small.ron");
    std::fs::write(&scenario, SMALL_COMPACTION).unwrap();
    let avx = run_with(&scenario, &dir, "avx", Some(("SDEM_SIMD", "avx")));
    let avx512 = run_with(&scenario, &dir, "avx512", Some(("SDEM_SIMD", "avx512")));
    assert_same_outputs(&avx, &avx512, "between SDEM_SIMD=avx and avx512");
}
