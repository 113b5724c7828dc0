#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, build-fuzz/) and runs each for a bounded time.
#   bash tests/fuzz/run.sh [SECONDS_PER_TARGET] [TARGET...]     (default 60 s; all of scene packing
#                                                               checkpoint curve sweep)
#   DEM_FUZZ_PARALLEL=1   the targets side by side (one process each) instead of one after another
#   DEM_FUZZ_KEEP=1       afterwards, minimise each target's corpus back into tests/fuzz/corpus/<target>/
#   DEM_FUZZ_NICE=19      the niceness of the fuzzers (default 19: a shared machine)
# The kept corpus tests/fuzz/corpus/<target>/ (in git, minimised with -merge=1) is read by every run,
# so a session continues where the last one stopped; new units and the seeds made here from the
# repository's own files go to build-fuzz/corpus/<target>/. Crashes land in
# tests/fuzz/findings/<target>/ (each one becomes a regression test); the log of each target is
# build-fuzz/logs/<target>.log. Needs clang and libclang-rt-14-dev (apt-get install clang libclang-rt-14-dev).
set -euo pipefail
cd "$(dirname "$0")/../.."
secs="${1:-60}"
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(scene packing checkpoint curve sweep)
for t in "${targets[@]}"; do
  case "$t" in scene|packing|checkpoint|curve|sweep) ;; *) echo "run.sh: no target '$t' (scene packing checkpoint curve sweep)" >&2; exit 2;; esac
done
CC=clang CXX=clang++ cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=Release -DDEM_FUZZ=ON -DDEM_BUILD_TESTS=OFF >/dev/null
cmake --build build-fuzz -j"$(nproc)" --target "${targets[@]/#/fuzz_}" >/dev/null
kept=tests/fuzz/corpus
work=build-fuzz/corpus
mkdir -p "$work"/{scene,packing,checkpoint,curve,sweep} "$kept"/{scene,packing,checkpoint,curve,sweep} build-fuzz/logs
cp data/scenes/*.toml tests/fuzz/seeds/scene/* "$work/scene/"   # seeds/: malformed shapes and --set lines (after %%)
head -c 4000 data/packings/n9261_phi0.70.txt > "$work/packing/n9261_head.txt"
printf '##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.003 0.001\n0.005 0.005 0.005 0.001\n' > "$work/packing/two.txt"
head -c 6000 data/paper_n9261/D2_phi0.700.csv > "$work/curve/d2_head.csv"
# Sweep seeds: the first byte picks the door (even: a table file, odd: a scene with [sweep]).
{ printf '\000'; cat data/powders/adhesion.tsv; } > "$work/sweep/adhesion.tsv"
printf '\000name contact.friction\nmu0 0.0\nmu05 0.5\n' > "$work/sweep/spaces.txt"
printf '\001[particles]\ncount = 60\n[sweep]\nkeys = ["contact.friction"]\nvalues = [[0.0], [0.5]]\nnames = ["a", "b"]\n' > "$work/sweep/scene.toml"
# A small real checkpoint (first byte 1: the target appends the checksum itself), when build/dem
# exists; the kept corpus holds one already.
if [ ! -e "$work/checkpoint/seed.ckpt" ] && [ -x build/dem ]; then
  tmp=$(mktemp -d)
  printf '[particles]\ncount = 60\n[integration]\nthreads = 1\n[protocol]\ncheckpoints_unloading = [0.70]\ncycle_phi_max = 0.72\ncompress_rate_tc = 1e-3\ncycle_rate_tc = 1e-3\nrelax_max_time_tc = 100\nmodes = ["D2"]\n[output]\nvtk = false\n' > "$tmp/s.toml"
  build/dem run "$tmp/s.toml" --out "$tmp/r" --stages prep --quiet >/dev/null 2>&1 || true
  if [ -e "$tmp/r/checkpoints/unloading_phi0.700.ckpt" ]; then
    { printf '\001'; head -c -8 "$tmp/r/checkpoints/unloading_phi0.700.ckpt"; } > "$work/checkpoint/seed.ckpt"
  fi
  rm -rf "$tmp"
fi

fuzz_one() {   # target: run it on the working corpus (new units) and the kept one (read only)
  local t=$1
  mkdir -p "tests/fuzz/findings/$t"
  nice -n "${DEM_FUZZ_NICE:-19}" build-fuzz/tests/fuzz/fuzz_$t "$work/$t" "$kept/$t" -max_total_time="$secs" \
    -rss_limit_mb=2048 -max_len=65536 -artifact_prefix="tests/fuzz/findings/$t/" -print_final_stats=1 \
    > "build-fuzz/logs/$t.log" 2>&1 || true
}

report() {     # target: its executions and time, and whether it left findings
  local t=$1
  echo "== fuzz_$t: $(grep -E 'stat::number_of_executed_units' "build-fuzz/logs/$t.log" | awk '{print $2}') executions," \
       "$(grep -E 'stat::average_exec_per_sec' "build-fuzz/logs/$t.log" | awk '{print $2}') per second, ${secs} s"
  grep -E "ERROR|SUMMARY|runtime error" "build-fuzz/logs/$t.log" | head -5 || true
  if ls "tests/fuzz/findings/$t"/crash-* "tests/fuzz/findings/$t"/leak-* "tests/fuzz/findings/$t"/timeout-* \
        "tests/fuzz/findings/$t"/oom-* >/dev/null 2>&1; then
    echo "fuzz_$t: findings in tests/fuzz/findings/$t/"; return 1
  fi
}

keep() {       # target: minimise kept + new units into a fresh folder, which becomes the kept corpus
  local t=$1 fresh="build-fuzz/merged/$t"
  rm -rf "$fresh"; mkdir -p "$fresh"
  nice -n "${DEM_FUZZ_NICE:-19}" build-fuzz/tests/fuzz/fuzz_$t -merge=1 -max_len=65536 -rss_limit_mb=2048 \
    "$fresh" "$kept/$t" "$work/$t" > "build-fuzz/logs/$t.merge.log" 2>&1
  rm -rf "${kept:?}/$t"; mv "$fresh" "$kept/$t"
  echo "kept corpus $t: $(find "$kept/$t" -type f | wc -l) files, $(du -sk "$kept/$t" | cut -f1) KiB"
}

if [ "${DEM_FUZZ_PARALLEL:-0}" = 1 ]; then
  for t in "${targets[@]}"; do echo "== fuzz_$t: ${secs} s (side by side)"; fuzz_one "$t" & done
  wait
else
  for t in "${targets[@]}"; do echo "== fuzz_$t: ${secs} s"; fuzz_one "$t"; done
fi
status=0
for t in "${targets[@]}"; do report "$t" || status=1; done
if [ "${DEM_FUZZ_KEEP:-0}" = 1 ]; then
  for t in "${targets[@]}"; do keep "$t"; done
fi
exit $status
