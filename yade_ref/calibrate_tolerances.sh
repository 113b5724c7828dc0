#!/usr/bin/env bash
# How far apart are two runs of ONE code that differ only by dt changed by 0.1 %? DEM is
# chaotic, so this spread is the floor under any cross-code tolerance. Same packings, rates
# and physics as data/yade (make_reference.sh). Writes data/yade/perturbed_*.csv; yade_ref/summarize.py tabulates them.
set -euo pipefail
cd "$(dirname "$0")/.."
out=data/yade
MATCHED=(--set integration.integrator=symplectic_euler --set contact.background_damping_kg_s=0 --set integration.threads=1)
for phi in 0.690 0.740 0.800; do
  for mode in D2 D3; do
    build/dem mode --packing "$out/packing_phi$phi.txt" --mode $mode --rate-tc 1e-4 --eps-max 0.12 \
      --set output.sample_strain=0.003 --set integration.dt_over_tc=0.02002 "${MATCHED[@]}" \
      --out "$out/perturbed_${mode}_phi$phi.csv" --force --quiet
    build/dem compare "$out/ours_${mode}_phi$phi.csv" "$out/perturbed_${mode}_phi$phi.csv" --labels "dt,dt*1.001" || true
  done
done
