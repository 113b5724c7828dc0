#!/usr/bin/env bash
# Installs the Debian packages the toolkit needs (run as root, or with sudo available).
# Usage: scripts/install-deps.sh [--only GROUPS] [--no-yade] [--bench] [--tex]
#   --only GROUPS  a comma list of build, run, test (default: all three). setup.sh installs build,
#                  then run while the compiler works; test.sh installs test (README, "Set-up time").
#       build  compilers and the libraries the C++ code and the Python module compile against
#       run    what the main job needs beyond the build: Snakemake, matplotlib, pandas, scipy
#       test   what only the tests need: pytest, YADE, Slurm + munge, VTK/xvfb, the notebook kernel,
#              pip/venv (the install test)
#   --no-yade   skip YADE (its own share is about 150 MB of .debs, a quarter of the whole); the YADE
#               cross-check tests are then skipped.
#   --bench     also LAMMPS and LIGGGHTS (for bench/run_benchmarks.py; not needed by the tests)
#   --tex       also LaTeX (pdflatex, booktabs, siunitx: about 135 MB to download): the test that compiles
#               every .tex table the toolkit writes runs only with it
set -euo pipefail
want_yade=1
want_bench=0
want_tex=0
groups="build,run,test"
while [ $# -gt 0 ]; do
  case "$1" in
    --only) groups="${2:-}"; shift ;;
    --only=*) groups="${1#--only=}" ;;
    --no-yade) want_yade=0 ;;
    --bench) want_bench=1 ;;
    --tex) want_tex=1 ;;
    *) echo "install-deps.sh: unknown option '$1' (known: --only build,run,test, --no-yade, --bench, --tex)" >&2; exit 2 ;;
  esac
  shift
done
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null; then SUDO="sudo"; else
    echo "install-deps.sh: needs root (or sudo) to run apt-get" >&2; exit 1; fi
fi
pkgs=()
for g in ${groups//,/ }; do
  case "$g" in
    build) pkgs+=(build-essential cmake pkg-config
                  libeigen3-dev libceres-dev libgoogle-glog-dev libgsl-dev
                  libtomlplusplus-dev libcli11-dev libgtest-dev nlohmann-json3-dev
                  python3 python3-dev pybind11-dev python3-numpy) ;;
    run) pkgs+=(python3-matplotlib python3-pandas python3-scipy snakemake) ;;
    test) pkgs+=(python3-pytest python3-pytest-xdist python3-vtk9 xvfb xauth
                 python3-nbformat python3-nbclient python3-ipykernel
                 python3-pip python3-setuptools python3-wheel python3-venv
                 slurm-wlm munge)
          [ "$want_yade" = 1 ] && pkgs+=(yade) ;;
    *) echo "install-deps.sh: unknown group '$g' in --only (known: build, run, test)" >&2; exit 2 ;;
  esac
done
[ "$want_bench" = 1 ] && pkgs+=(lammps liggghts openmpi-bin time)
[ "$want_tex" = 1 ] && pkgs+=(texlive-latex-base texlive-latex-recommended texlive-science)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps.sh: all packages already installed ($groups)" >&2
  exit 0
fi
echo "install-deps.sh: installing ($groups) ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
# The package lists: updated unless an update wrote them within the hour (setup.sh's second group
# follows its first by a minute).
lists_age=$(( $(date +%s) - $(stat -c %Y /var/lib/apt/lists 2>/dev/null || echo 0) ))
if [ "$lists_age" -gt 3600 ] || ! ls /var/lib/apt/lists/*Packages* >/dev/null 2>&1; then
  $SUDO apt-get update -qq
fi
# --force-unsafe-io: dpkg skips its fsync per unpacked file (as Debian's container images do); a
# power cut during the install can then leave a package to reinstall, nothing else.
$SUDO apt-get install -y -qq --no-install-recommends -o Dpkg::Options::=--force-unsafe-io "${missing[@]}"
