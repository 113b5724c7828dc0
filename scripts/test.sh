#!/usr/bin/env bash
# All tests: C++ (ctest) and the pipeline (pytest). Needs scripts/setup.sh first. Installs the
# tests' own packages (YADE, Slurm, pytest, ...; install-deps.sh --only test) while the C++ tests
# build; DEM_INSTALL_OPTS=--no-yade leaves YADE out (its cross-checks are then skipped).
# Extra checks, not run here: the sanitizer build and the fuzzers (README, "Keeping it correct").
set -euo pipefail
cd "$(dirname "$0")/.."
cmake --build build -j"$(nproc)" > build/test-build.log 2>&1 &
builder=$!
# shellcheck disable=SC2086
bash scripts/install-deps.sh --only test ${DEM_INSTALL_OPTS:-} || { kill "$builder" 2>/dev/null; exit 1; }
wait "$builder" || { tail -40 build/test-build.log >&2; echo "test.sh: the build failed (build/test-build.log)" >&2; exit 1; }
# ctest on every core: each test writes its own temporary files (distinct names; tests/cpp), the
# longest are model fits of 15-27 s, and nothing in them is timed; 153-164 s serial, 56-59 s on two (fresh clones, idle).
(cd build && ctest -j"$(nproc)" --output-on-failure)
# build/python: the Python module demtk (docs/python.md), for the tests and the notebook's kernel.
export PYTHONPATH="$PWD/build/python${PYTHONPATH:+:$PYTHONPATH}"
# Passive OpenMP waiting: the pipeline tests start multi-threaded runs, and spinning threads on a
# machine busy with other jobs run up to 35x slower (docs/benchmarks.md).
# Two or more cores: the modules run on min(cores, 4) workers (pytest-xdist; conftest.py keeps a module on one worker
# and the Slurm modules on one); the README gives the suite's time measured in a fresh clone.
workers=()
if [ "$(nproc)" -ge 2 ] && /usr/bin/python3 -c "import xdist" 2> /dev/null; then
  n=$(nproc); [ "$n" -gt 4 ] && n=4
  workers=(-n "$n" --dist loadgroup)
fi
OMP_WAIT_POLICY=passive /usr/bin/python3 -m pytest -q "${workers[@]}" tests/python "$@"
