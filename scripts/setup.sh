#!/usr/bin/env bash
# Sets up everything on a fresh Debian 12 machine: Debian packages (via install-deps.sh),
# then a Release build in build/. Safe to run again (skips what is done).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh "$@"
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
# Only what the main job needs (the runner and the Python module): the C++ tests are about a third
# of the build's CPU time (README, "Set-up time") and scripts/test.sh builds them.
targets=(dem)
if cmake --build build --target help | grep "demtk_py" >/dev/null; then targets+=(demtk_core demtk_py); fi
cmake --build build -j"$(nproc)" --target "${targets[@]}"
echo "setup.sh: built build/dem ($(build/dem --help | head -1))" >&2
if [ -d build/python/demtk ]; then
  PYTHONPATH="$PWD/build/python" /usr/bin/python3 -c "import demtk" &&
    echo "setup.sh: built the Python module demtk: PYTHONPATH=$PWD/build/python /usr/bin/python3 -c 'import demtk' (docs/python.md)" >&2
fi
