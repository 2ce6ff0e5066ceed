#!/bin/sh
# Coverage-guided fuzzing of every file sdem reads (see docs/robustness.md).
#
#   tools/fuzz.sh [SECONDS] [TARGET...]
#
# Runs each target (default: all of scenario sample_file shape_file checkpoint mcap) for
# SECONDS seconds (default 60) or RUNS executions (environment, default 1000000), whichever
# comes first, and prints its executions, time and coverage (libFuzzer's cov: and ft:).
# Needs `cargo install cargo-fuzz` and a nightly toolchain (`rustup toolchain install nightly`).
# Environment: RUNS, SANITIZER (none, the default, or address), CARGO_TARGET_DIR (default
# fuzz/target), NICE (default 15).
#
# Corpora: fuzz/corpus/<target>/ (generated, not in git) starts from the shipped files
# (scenarios/*.ron, scenarios/*.csv, tests/data/*.bin) and fuzz/seeds/<target>/ (small
# checkpoints, MCAP logs and shape files written by sdem). A crash is saved as
# fuzz/artifacts/<target>/crash-*; reproduce it with
#   cargo +nightly fuzz run -s none <target> fuzz/artifacts/<target>/crash-...
set -eu
cd "$(dirname "$0")/.."
seconds=${1:-60}
[ $# -gt 0 ] && shift
targets=${*:-scenario sample_file shape_file checkpoint mcap}
runs=${RUNS:-1000000}
sanitizer=${SANITIZER:-none}
target_dir=${CARGO_TARGET_DIR:-$PWD/fuzz/target}
nice=${NICE:-15}
mkdir -p fuzz/logs
for t in $targets; do
    corpus=fuzz/corpus/$t
    mkdir -p "$corpus" "fuzz/seeds/$t"
    case $t in
    scenario) cp scenarios/*.ron "$corpus/" ;;
    sample_file) cp scenarios/*.csv "$corpus/" ;;
    checkpoint) cp tests/data/*.bin "$corpus/" ;;
    esac
    log=fuzz/logs/$t.log
    echo "== $t: up to $runs executions or $seconds s"
    nice -n "$nice" cargo +nightly fuzz run --fuzz-dir fuzz --sanitizer "$sanitizer" \
        --target-dir "$target_dir" "$t" "$corpus" "fuzz/seeds/$t" -- \
        -runs="$runs" -max_total_time="$seconds" -timeout=30 -print_final_stats=1 >"$log" 2>&1 || {
        tail -n 40 "$log"
        echo "== $t: FAILED (see $log and fuzz/artifacts/$t/)"
        exit 1
    }
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
    done_line=$(grep -E '^#[0-9]+[[:space:]]+(DONE|INITED)' "$log" | tail -n 1)
    secs=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$log")
    echo "== $t: $execs executions in ${secs:-?} s; final: $done_line"
done
