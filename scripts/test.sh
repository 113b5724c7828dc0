#!/usr/bin/env bash
# All tests: C++ (ctest) and the pipeline (pytest). Needs scripts/setup.sh first.
# Extra checks, not run here: the sanitizer build and the fuzzers (README, "Keeping it correct").
set -euo pipefail
cd "$(dirname "$0")/.."
cmake --build build -j"$(nproc)" >/dev/null
(cd build && ctest --output-on-failure)
# build/python: the Python module demtk (docs/python.md), for the tests and the notebook's kernel.
export PYTHONPATH="$PWD/build/python${PYTHONPATH:+:$PYTHONPATH}"
# Passive OpenMP waiting: the pipeline tests start multi-threaded runs, and spinning threads on a
# machine busy with other jobs run up to 35x slower (docs/benchmarks.md).
OMP_WAIT_POLICY=passive /usr/bin/python3 -m pytest -q tests/python "$@"
