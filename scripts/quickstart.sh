#!/usr/bin/env bash
# The main job on the default quick scene: run the whole protocol, fit, plot.
# Results go to runs/quickstart (refused if it holds finished results; pass --force to redo).
set -euo pipefail
cd "$(dirname "$0")/.."
out=runs/quickstart
build/dem run data/scenes/quickstart.toml --out "$out" "$@"
build/dem fit "$out" "$@"
echo "quickstart.sh: curves in $out/deviatoric, fit tables in $out/fit, plots in $out/plots" >&2
