#!/usr/bin/env bash
# The bytes of every curve, checkpoint and VTK file of short runs through each door (issue 34:
# a refactor keeps them): a quickstart member (`dem run --stages prep` + `dem mode`, as the
# ensemble's tasks), a frictional scene with simple shear, a path scene, a stress-controlled
# preparation stage, and the demtk (Python) route (run_prep_stage, run_mode, run_stage).
#
#   scripts/bits_check.sh DEM PYDIR OUT       # DEM: a dem binary; PYDIR: the folder holding demtk/
#   scripts/bits_check.sh --compare A/sums.txt B/sums.txt
#
# Writes OUT/sums.txt ("sha256  case/relative/path", manifests and scene copies aside: they hold the
# command line and the version), the fit tables of the frictional run (`dem fit`), and `dem fit` and `dem model` on a copy of
# data/figure3_n9261 (an ensemble: fit_ensemble, calibrate). Small N and short strains: about 40 s on one core.
set -euo pipefail
if [[ "${1:-}" == "--compare" ]]; then
  if diff -u "$2" "$3"; then echo "bits_check: the same bytes ($(wc -l < "$2") files)"; exit 0; fi
  echo "bits_check: bytes differ" >&2; exit 1
fi
DEM=$(readlink -f "$1"); PYDIR=$(readlink -f "$2"); OUT=$3
ROOT=$(cd "$(dirname "$0")/.." && pwd)
rm -rf "$OUT"; mkdir -p "$OUT"
S=(--set particles.count=200 --set integration.threads=1 --quiet)

# 1. A quickstart member: its preparation, then a mode task from a checkpoint.
"$DEM" run "$ROOT/data/scenes/quickstart.toml" --out "$OUT/qs" --stages prep "${S[@]}" --set ensemble.packings=1 \
  --set particles.seed=3 --set output.vtk=true --set 'protocol.checkpoints_unloading=[0.80]'
"$DEM" mode --packing "$OUT/qs/checkpoints/unloading_phi0.800.ckpt" --mode D3 --eps-max 0.02 --rate-tc 2e-4 \
  --threads 1 --out "$OUT/qs/D3.csv" --quiet

# 2. Friction with a simple shear mode (the sheared cell, the history kernels).
"$DEM" run "$ROOT/data/scenes/friction_example.toml" --out "$OUT/fr" "${S[@]}" --set output.vtk=true \
  --set 'protocol.checkpoints_unloading=[0.72]' --set 'protocol.modes=["D2","SS_xz"]' \
  --set protocol.eps_d_max=0.02 --set protocol.deviatoric_rate_tc=2e-4

"$DEM" fit "$OUT/fr" > /dev/null   # the fit tables of its curves

# 3. Loading paths (strain reversal, side-stress servo, simple shear at constant normal stress).
"$DEM" run "$ROOT/data/scenes/paths_example.toml" --out "$OUT/paths" "${S[@]}" --set output.vtk=true \
  --set 'protocol.checkpoints_unloading=[0.80]' --set 'protocol.modes=["reversal","triaxial","shear_cns"]' \
  --set protocol.deviatoric_rate_tc=1e-3

# 4. A stress-controlled preparation stage (a one-stage path) and a preparation list.
cat > "$OUT/prep.toml" <<TOML
[particles]
count = 200
seed = 2
[protocol]
initial_phi = 0.3
preparation = [
  { name = "gas", kind = "compress", rate_tc = 1e-3, until = { phi = 0.5 } },
  { name = "press", kind = "pressure", target_Pa = 1e5, rate_tc = 1e-3, until = { ke_ratio = 1e-3 }, max_time_tc = 300, checkpoint_name = "pressed" },
  { name = "relax", kind = "relax", until = { ke_ratio = 1e-4 }, max_time_tc = 200 },
]
modes_from = "pressed"
modes = ["D2"]
deviatoric_rate_tc = 1e-3
eps_d_max = 0.01
[integration]
threads = 1
[output]
vtk = true
TOML
"$DEM" run "$OUT/prep.toml" --out "$OUT/prep" --quiet

# 5. demtk: the preparation stage by stage, a mode and a sheared run_stage from Python.
PYTHONPATH="$PYDIR" /usr/bin/python3 - "$ROOT" "$OUT/py" <<'PY'
import os, sys
import demtk
root, out = sys.argv[1], sys.argv[2]
os.makedirs(out)
scene = demtk.load_scene(os.path.join(root, "data/scenes/quickstart.toml"),
                         set={"particles.count": 200, "ensemble.packings": 1, "integration.threads": 1,
                              "protocol.checkpoints_unloading": [0.80], "protocol.eps_d_max": 0.02,
                              "protocol.deviatoric_rate_tc": 2e-4})
state = demtk.random_packing(scene, 0.3)
saved = {}
def keep(phi, st):
    saved[round(phi, 3)] = st
    st.save_checkpoint(os.path.join(out, "ck_%.3f.ckpt" % phi), scene, "py")
for name in ["compress", "relax", "cycle_loading", "cycle_unloading"]:
    demtk.run_prep_stage(scene, state, name, os.path.join(out, name + ".csv"), on_checkpoint=keep)
demtk.run_mode(scene, saved[0.8], "D2", os.path.join(out, "D2.csv"))
st = demtk.read_checkpoint(os.path.join(out, "ck_0.800.ckpt")).state
demtk.run_stage(scene, st, "shear", [[0, 0, 2 * scene.deviatoric_rate], [0, 0, 0], [0, 0, 0]], "eps_d", 0.01,
                out=os.path.join(out, "shear.csv"), vtk_dir="")
PY

# 6. The ensemble fit (`dem fit` on an ensemble folder) and the constitutive model (`dem model`)
# on a copy of the committed N = 9261 ensemble's member curves.
mkdir -p "$OUT/ens" && cp -r "$ROOT/data/figure3_n9261/members" "$ROOT/data/figure3_n9261/ensemble" "$OUT/ens/"
"$DEM" fit "$OUT/ens" --no-plots > /dev/null 2>&1
"$DEM" model "$OUT/ens" --out "$OUT/model" --no-jackknife --no-plots > /dev/null 2>&1

cd "$OUT"
find . -type f \( -name '*.csv' -o -name '*.ckpt' -o -name '*.txt' -o -name '*.vtu' -o -name '*.pvd' -o -path './fr/fit/*' -o -path './ens/fit/*' -o -path './ens/ensemble/*' -o -path './model/*' \) \
  ! -name sums.txt | LC_ALL=C sort | xargs sha256sum > sums.txt
echo "bits_check: $(wc -l < sums.txt) files in $OUT/sums.txt" >&2
