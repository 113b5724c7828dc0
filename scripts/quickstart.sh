#!/usr/bin/env bash
# The main job on the default quick scene: an ensemble of 10 packings of 1000 spheres through the
# whole protocol, D2 and D3 from three volume fractions, averaged with 95 % bands, fitted, plotted
# (Snakemake underneath, one job per packing on each core; at the end, where the time went: run.json).
# Results in runs/quickstart.
# Run again to continue an interrupted run; pass --force to redo a finished one.
set -euo pipefail
cd "$(dirname "$0")/.."
out=runs/quickstart
build/dem ensemble data/scenes/quickstart.toml --out "$out" "$@"
echo "quickstart.sh: mean curves with 95 % bands in $out/ensemble, fit tables in $out/fit, plots in $out/plots" >&2
