#!/usr/bin/env bash
# Regenerates data/yade/: YADE and our runner on the same N = 9261 packings (three volume
# fractions from the unloading branch of data/scenes/yade_reference.toml), D2 and D3, with
# matched physics (docs/yade.md). YADE needs 12-15 minutes per run on one core (0.45 M particle-steps/s).
#
#   bash yade_ref/make_reference.sh [JOBS]      (JOBS parallel YADE runs, default 2)
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=${1:-2}
run=runs/yade_reference
out=data/yade
RATE_TC=1e-4; EPS=0.12; SAMPLE=0.003
if [ ! -f "$run/checkpoints/unloading_phi0.690.txt" ]; then
  build/dem run data/scenes/yade_reference.toml --out "$run" --stages prep --quiet
fi
mkdir -p "$out"
for phi in 0.690 0.740 0.800; do cp "$run/checkpoints/unloading_phi$phi.txt" "$out/packing_phi$phi.txt"; done
MATCHED=(--set integration.integrator=symplectic_euler
         --set contact.background_damping_kg_s=0 --set integration.threads=1)
for phi in 0.690 0.740 0.800; do
  for mode in D2 D3; do
    build/dem mode --packing "$out/packing_phi$phi.txt" --mode "$mode" --rate-tc $RATE_TC --eps-max $EPS \
      --set output.sample_strain=$SAMPLE "${MATCHED[@]}" --out "$out/ours_${mode}_phi$phi.csv" --force --quiet
  done
done
cmds=()
for phi in 0.690 0.740 0.800; do
  for mode in D2 D3; do
    cmds+=("yade -n -x -j1 yade_ref/run_mode.py --packing $out/packing_phi$phi.txt --mode $mode --rate-tc $RATE_TC --eps-max $EPS --sample-strain $SAMPLE --out $out/yade_${mode}_phi$phi.csv")
  done
done
printf '%s\n' "${cmds[@]}" > "$out/COMMANDS.txt"
printf '%s\0' "${cmds[@]}" | xargs -0 -P "$jobs" -I{} bash -c '{} > /dev/null 2>>data/yade/yade_stderr.log'
grep "particle-steps" "$out/yade_stderr.log" || true
