#!/usr/bin/env bash
# Installs every Debian package the toolkit needs (run as root, or with sudo available).
# Usage: scripts/install-deps.sh [--no-yade] [--bench] [--tex]
#   --no-yade   skip YADE (about 1 GiB with its dependencies); the YADE cross-check tests are then skipped.
#   --bench     also LAMMPS and LIGGGHTS (for bench/run_benchmarks.py; not needed by the tests)
#   --tex       also LaTeX (pdflatex, booktabs, siunitx: about 135 MB to download): the test that compiles
#               every .tex table the toolkit writes runs only with it
set -euo pipefail
want_yade=1
want_bench=0
want_tex=0
for a in "$@"; do
  case "$a" in
    --no-yade) want_yade=0 ;;
    --bench) want_bench=1 ;;
    --tex) want_tex=1 ;;
    *) echo "install-deps.sh: unknown option '$a' (known: --no-yade, --bench, --tex)" >&2; exit 2 ;;
  esac
done
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null; then SUDO="sudo"; else
    echo "install-deps.sh: needs root (or sudo) to run apt-get" >&2; exit 1; fi
fi
pkgs=(build-essential cmake pkg-config
      libeigen3-dev libceres-dev libgoogle-glog-dev libgsl-dev
      libtomlplusplus-dev libcli11-dev libgtest-dev
      nlohmann-json3-dev
      python3 python3-pytest python3-numpy python3-matplotlib
      python3-vtk9 xvfb xauth
      python3-dev pybind11-dev python3-pandas python3-scipy python3-nbformat python3-nbclient python3-ipykernel
      python3-pip python3-setuptools python3-wheel python3-venv
      snakemake slurm-wlm munge)
[ "$want_yade" = 1 ] && pkgs+=(yade)
[ "$want_bench" = 1 ] && pkgs+=(lammps liggghts openmpi-bin time)
[ "$want_tex" = 1 ] && pkgs+=(texlive-latex-base texlive-latex-recommended texlive-science)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps.sh: all packages already installed" >&2
  exit 0
fi
echo "install-deps.sh: installing ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
