#!/bin/bash
# Ours on the frictional packing: D2 and constant side stress (triax), at dt = t_c/25 and with dt perturbed
# by -0.2 ... +0.5 % (the chaos floor). Run from the repository root: bash data/yade_friction/run_ours.sh
set -e
D=data/yade_friction
for dt in 0.04 0.03992 0.04004 0.04008 0.04012 0.0402; do
  tag=$([ "$dt" = 0.04 ] && echo ours || echo perturbed)
  build/dem mode --scene $D/scene.toml --packing $D/packing_phi0.700.txt --mode D2 --rate-tc 1e-4 --eps-max 0.2 \
      --set integration.dt_over_tc=$dt --quiet --force --out $D/${tag}_D2_dt$dt.csv
  build/dem mode --scene $D/scene.toml --packing $D/packing_phi0.700.txt --mode triax \
      --set integration.dt_over_tc=$dt --quiet --force --out $D/${tag}_triax_dt$dt.csv
done
