#!/usr/bin/env bash
# All tests: C++ (ctest) and the pipeline (pytest). Needs scripts/setup.sh first.
# Opt-in long tests: DEM_LONG_TESTS=1 scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
cmake --build build -j"$(nproc)" >/dev/null
(cd build && ctest --output-on-failure)
/usr/bin/python3 -m pytest -q tests/python "$@"
