#!/bin/bash
# Hertz-Mindlin against YADE (docs/contact_models.md, "Against YADE"): ours at dt = T_R/25 and with dt
# perturbed by -0.2 ... +0.5 % (the chaos floor), D2 to eps_d = 0.2 and constant side stress to
# eps_zz = -0.10; then YADE once each. From the repository root: bash data/yade_hm/run.sh [DEM]
set -e
DEM=${1:-build/dem}
D=data/yade_hm
P=data/yade_friction/packing_phi0.700.txt
for dt in 0.04 0.03992 0.04004 0.04008 0.04012 0.0402; do
  tag=$([ "$dt" = 0.04 ] && echo ours || echo perturbed)
  "$DEM" mode --scene $D/scene.toml --packing $P --mode D2 --rate-tc 1e-4 --eps-max 0.2 \
      --set integration.dt_over_tc=$dt --quiet --force --out $D/${tag}_D2_dt$dt.csv
  "$DEM" mode --scene $D/scene.toml --packing $P --mode triax \
      --set integration.dt_over_tc=$dt --quiet --force --out $D/${tag}_triax_dt$dt.csv
done
C="--packing $P --rate-tc 1e-4 --dt-over-tc 0.04 --r-min 0.0005 --law mindlin --young 1.82e11 --poisson 0.3 \
   --friction 0.5 --en 1 --sample-strain 0.002"
yade -n -x -j1 yade_ref/run_mode.py $C --mode D2 --eps-max 0.2 --out $D/yade_D2_phi0.700.csv
yade -n -x -j1 yade_ref/run_mode.py $C --mode uniaxial_z --side-stress-p0 1 --eps-max 0.1 --out $D/yade_triax_phi0.700.csv
