#!/usr/bin/env bash
# Sets up everything on a fresh Debian 12 machine: Debian packages (via install-deps.sh),
# then a Release build in build/. Safe to run again (skips what is done).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh "$@"
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)"
echo "setup.sh: built build/dem ($(build/dem --help | head -1))" >&2
if [ -d build/python/demtk ]; then
  PYTHONPATH="$PWD/build/python" /usr/bin/python3 -c "import demtk" &&
    echo "setup.sh: built the Python module demtk: PYTHONPATH=$PWD/build/python /usr/bin/python3 -c 'import demtk' (docs/python.md)" >&2
fi
