#!/usr/bin/env bash
# Sets up what the main job needs on a fresh Debian 12 machine: the build packages, then the build
# (in the background) while the run packages install beside it (README, "Set-up time"). The tests'
# own packages (YADE, Slurm, pytest, ...) come with scripts/test.sh. Safe to run again (skips what
# is done). Options go to install-deps.sh (e.g. --bench, --tex).
set -euo pipefail
cd "$(dirname "$0")/.."
t0=$(date +%s)
bash scripts/install-deps.sh --only build "$@"
t1=$(date +%s)
mkdir -p build
log=build/setup-build.log
build() {
  cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
  # Only what the main job needs (the runner and the Python module): the C++ tests are about a third
  # of the build's CPU time and scripts/test.sh builds them.
  local targets=(dem)
  if cmake --build build --target help | grep "demtk_py" >/dev/null; then targets+=(demtk_core demtk_py); fi
  cmake --build build -j"$(nproc)" --target "${targets[@]}"
}
build > "$log" 2>&1 &
builder=$!
deps_ok=1
bash scripts/install-deps.sh --only run "$@" || deps_ok=0
t2=$(date +%s)
if ! wait "$builder"; then
  tail -40 "$log" >&2
  echo "setup.sh: the build failed (the whole log: $log)" >&2
  exit 1
fi
[ "$deps_ok" = 1 ] || { echo "setup.sh: installing the run packages failed (above); run bash scripts/setup.sh again" >&2; exit 1; }
t3=$(date +%s)
grep -iE "warning" "$log" >&2 || true
echo "setup.sh: built build/dem ($(build/dem --help | head -1))" >&2
if [ -d build/python/demtk ]; then
  PYTHONPATH="$PWD/build/python" /usr/bin/python3 -c "import demtk" &&
    echo "setup.sh: built the Python module demtk: PYTHONPATH=$PWD/build/python /usr/bin/python3 -c 'import demtk' (docs/python.md)" >&2
fi
echo "setup.sh: $((t3 - t0)) s: build packages $((t1 - t0)) s, then the build beside the run packages ($((t2 - t1)) s) until $((t3 - t1)) s" >&2
