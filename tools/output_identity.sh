#!/usr/bin/env bash
# Runs a fixed set of output commands with one sdem binary and prints the sha256 of every file
# they write (summary.txt lines with wall-clock times are dropped first). Run it with the binary
# before and after a change of the output code and diff the two listings:
#
#   tools/output_identity.sh /path/to/old/sdem > before.txt
#   tools/output_identity.sh target/release/sdem > after.txt
#   diff before.txt after.txt
#
# Covers: `run --mcap` (box, frictionless; box, frictional; periodic; meshfree), `render` (PNG
# and SVG, each log), `plot` (PNG and SVG, from a run directory and from a log), `inspect`.
set -euo pipefail
bin=$(realpath "$1")
repo=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
cp "$repo/scenarios/meshfree_bouncing_disc_grains.csv" .

cat > box.ron <<'R'
Scenario(
    name: "box", seed: 3,
    sample: (count: 120, box_width: 0.4, box_height: 0.4,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    loading: [ Isotropic(rate: Constant(2e-2), until: PackingFraction(0.84)) ],
    output: (every: 400),
)
R
sed -e 's/name: "box"/name: "friction"/' \
    -e 's/output:/contact: (friction: (grains: 0.5, walls: 0.3, stiffness_ratio: 1.0)),\n    output:/' box.ron > friction.ron
sed -e 's/name: "box"/name: "periodic"/' \
    -e 's/output:/boundary: Periodic,\n    output:/' box.ron > periodic.ron
sed -e 's/Time(4.0)/Time(0.2)/' -e 's/every: 1)/every: 2)/' \
    "$repo/scenarios/meshfree_bouncing_disc.ron" > meshfree.ron

for s in box friction periodic meshfree; do
  "$bin" run "$s.ron" --out "run_$s" --quiet --threads 2 --mcap "run_$s/$s.mcap" > /dev/null
  "$bin" render "run_$s/$s.mcap" --out "render_$s.png" --size 400 > /dev/null
  "$bin" render "run_$s/$s.mcap" --frame 0 --out "render_$s.svg" --size 400 > /dev/null
  "$bin" inspect "run_$s/$s.mcap" > "inspect_$s.txt"
  "$bin" plot "run_$s" --out "plot_dir_$s" > /dev/null
  "$bin" plot "run_$s/$s.mcap" --out "plot_log_$s" --svg > /dev/null
  grep -v -i "second\|wall\|elapsed\|threads\|speed" "run_$s/summary.txt" > "run_$s/summary.filtered" || true
  rm "run_$s/summary.txt"
done
find . -type f ! -name '*.ron' ! -name '*grains.csv' -o -path './run_*/grains.csv' | sort | xargs sha256sum
