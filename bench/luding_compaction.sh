#!/bin/bash
# Adhesive compaction: data/luding_compaction/scene.toml at three adhesions, preparation stages
# only (compress, relax, isotropic cycle). Writes runs/luding_compaction/kc*/ and collects the
# curves' nu and p into data/luding_compaction/ (see docs/contact_models.md).
#   bash bench/luding_compaction.sh [path/to/dem]
set -euo pipefail
cd "$(dirname "$0")/.."
DEM=${1:-build/dem}
for kc in 0 1e8 5e8; do
  out=runs/luding_compaction/kc$kc
  "$DEM" run data/luding_compaction/scene.toml --out "$out" --stages prep --force --threads 1 \
    --set contact.luding_kc_N_m=$kc
done
/usr/bin/python3 bench/luding_compaction.py runs/luding_compaction data/luding_compaction
