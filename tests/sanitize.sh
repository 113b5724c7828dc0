#!/usr/bin/env bash
# The suite under AddressSanitizer + UndefinedBehaviorSanitizer (GCC, build-asan/; or clang, below). Opt-in: not part
# of scripts/test.sh or CI (minutes of build, the tests run 2-5x slower). Record: tests/SANITIZE.md.
#   bash tests/sanitize.sh                  build, then all of: cpp python demtk-fuzz
#   bash tests/sanitize.sh cpp              the C++ tests (ctest; leak checking on)
#   bash tests/sanitize.sh python [ARGS]    pytest tests/python against the instrumented dem and demtk
#                                           (ARGS go to pytest, e.g. tests/python/test_python_module.py)
#   bash tests/sanitize.sh demtk-fuzz [SECONDS] [SEED]   tests/fuzz/fuzz_demtk.py on the instrumented demtk
#   DEM_SANITIZE_CC=clang ...               clang instead of GCC: the fuzz build (build-fuzz, ASan + UBSan and
#                                           libFuzzer's counters), shared with tests/fuzz/run.sh, also
#                                           builds the tests and demtk; clang's UBSan checks more (vptr,
#                                           function) and one build serves both
# Every sanitizer report of every process (the tests, dem started by them, python) is written to
# <build>/sanitizer-logs/ (ASAN_OPTIONS/UBSAN_OPTIONS log_path), so a report is found even when a
# test captures the process's stderr or accepts its failure; the script ends with their count.
# Python: the instrumented extension needs the ASan runtime loaded first, so python runs with
# LD_PRELOAD=libasan (every child inherits it) and detect_leaks=0 (CPython keeps its objects to
# the end by design). The Python tests find build/ by path; they run from a shadow tree of links
# (<build>/shadow: every top-level entry of the repository, with build -> <build>).
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
what=${1:-all}
[ $# -gt 0 ] && shift
if [ "${DEM_SANITIZE_CC:-gcc}" = clang ]; then
  bdir=build-fuzz cc=clang cxx=clang++ mode=-DDEM_FUZZ=ON
  runtime=$(clang -print-file-name=libclang_rt.asan-x86_64.so)
else
  bdir=build-asan cc=gcc cxx=g++ mode=-DDEM_SANITIZE=ON
  runtime=$(gcc -print-file-name=libasan.so)
fi
logs=$repo/$bdir/sanitizer-logs

build() {      # the targets named (no LTO for demtk: its link would take minutes under ASan)
  CC=$cc CXX=$cxx cmake -S . -B "$bdir" -DCMAKE_BUILD_TYPE=Release "$mode" -DDEM_BUILD_TESTS=ON -DDEM_PYTHON=ON \
    -DCMAKE_INTERPROCEDURAL_OPTIMIZATION=OFF >/dev/null
  cmake --build "$bdir" -j"$(nproc)" --target "$@" > "$bdir/sanitize-build.log" 2>&1 \
    || { tail -30 "$bdir/sanitize-build.log" >&2; echo "sanitize.sh: the build failed" >&2; exit 1; }
  mkdir -p "$logs"
}

# A report halts the process (no recovery) and is logged to $logs/{asan,ubsan}.PID.
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:abort_on_error=1:log_path=$logs/ubsan"
asan_common="abort_on_error=1:log_path=$logs/asan"

run_cpp() {
  local t0=$SECONDS
  ASAN_OPTIONS="$asan_common:detect_leaks=1" OMP_WAIT_POLICY=passive \
    ctest --test-dir "$bdir" --output-on-failure -j1 "$@" 2>&1 | tee "$bdir/sanitize-cpp.log" | tail -5 || true
  echo "cpp: $((SECONDS - t0)) s"
}

shadow() {     # $bdir/shadow: the repository's entries, build -> $bdir
  local s=$repo/$bdir/shadow e
  rm -rf "$s"; mkdir -p "$s"
  for e in "$repo"/* "$repo"/.[!.]*; do
    case "$(basename "$e")" in build|build-*) continue;; esac
    ln -s "$e" "$s/$(basename "$e")"
  done
  ln -s "$repo/$bdir" "$s/build"
  echo "$s"
}

with_asan_python() {
  LD_PRELOAD="$runtime" ASAN_OPTIONS="$asan_common:detect_leaks=0" \
    OMP_WAIT_POLICY=passive PYTHONPATH="$repo/$bdir/python" "$@"
}

run_python() {
  local s t0=$SECONDS
  s=$(shadow)
  (cd "$s" && with_asan_python /usr/bin/python3 -m pytest -q -p no:cacheprovider "${@:-tests/python}") 2>&1 \
    | tee "$bdir/sanitize-python.log" | tail -15 || true
  echo "python: $((SECONDS - t0)) s"
}

run_demtk_fuzz() {
  local t0=$SECONDS
  with_asan_python /usr/bin/python3 tests/fuzz/fuzz_demtk.py --seconds "${1:-600}" --seed "${2:-3}" --hang 600 2>&1 \
    | tee "$bdir/sanitize-demtk-fuzz.log" | tail -5 || true
  echo "demtk-fuzz: $((SECONDS - t0)) s"
}

summary() {
  local n
  n=$(find "$logs" -type f | wc -l)
  echo "sanitizer reports: $n (in $logs)"
  [ "$n" -eq 0 ] || { grep -h -m1 -E "ERROR: AddressSanitizer|runtime error|ERROR: LeakSanitizer" "$logs"/* | sort | uniq -c; exit 1; }
}

case "$what" in
  cpp) build dem dem_tests; run_cpp "$@";;
  python) build dem demtk_core; run_python "$@";;
  demtk-fuzz) build demtk_core; run_demtk_fuzz "$@";;
  all) build dem dem_tests demtk_core; run_cpp; run_python; run_demtk_fuzz 600;;
  build) build dem dem_tests demtk_core;;
  *) echo "sanitize.sh: cpp, python [PYTEST ARGS], demtk-fuzz [SECONDS] [SEED], build or nothing (all)" >&2; exit 2;;
esac
summary
