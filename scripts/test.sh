#!/usr/bin/env bash
# All tests: C++ (ctest) and the pipeline (pytest). Needs scripts/setup.sh first.
# Extra checks, not run here: the sanitizer build and the fuzzers (README, "Keeping it correct").
set -euo pipefail
cd "$(dirname "$0")/.."
cmake --build build -j"$(nproc)" >/dev/null
(cd build && ctest --output-on-failure)
# Passive OpenMP waiting: the pipeline tests start multi-threaded runs, and spinning threads on a
# machine busy with other jobs run up to 35x slower (docs/benchmarks.md).
OMP_WAIT_POLICY=passive /usr/bin/python3 -m pytest -q tests/python "$@"
