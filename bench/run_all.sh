#!/usr/bin/env bash
# Regenerates every benchmark table and chart in docs/ (about 45 minutes on 2 cores; run on a
# quiet machine). Needs: scripts/setup.sh, and for the peer codes scripts/install-deps.sh --bench.
# The stored YADE reference (data/yade) is separate: bash yade_ref/make_reference.sh (hours).
set -euo pipefail
cd "$(dirname "$0")/.."
/usr/bin/python3 bench/run_benchmarks.py        # docs/benchmarks.md: ours vs YADE/LAMMPS/LIGGGHTS, N scaling
/usr/bin/python3 bench/stability_map.py         # docs/stability.md, docs/stability_map.png
/usr/bin/python3 bench/accuracy_cost.py         # docs/accuracy_cost.md, docs/accuracy_cost.png
/usr/bin/python3 bench/skin_scan.py            # docs/skin_scan.md, docs/skin_scan.png: the cost model behind the auto skin
/usr/bin/python3 bench/fit_identifiability.py   # docs/fit_identifiability.md, docs/fit_identifiability.png
/usr/bin/python3 yade_ref/summarize.py          # docs/yade_reference.md, docs/yade_*.png
