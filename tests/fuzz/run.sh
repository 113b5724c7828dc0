#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, build-fuzz/) and runs each for a bounded time.
#   bash tests/fuzz/run.sh [SECONDS_PER_TARGET]      (default 60)
# Seeds come from the repository's own files; crashes land in tests/fuzz/findings/<target>/
# (each one becomes a regression test). Needs clang and libclang-rt-14-dev
# (apt-get install clang libclang-rt-14-dev).
set -euo pipefail
cd "$(dirname "$0")/../.."
secs="${1:-60}"
CC=clang CXX=clang++ cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=Release -DDEM_FUZZ=ON -DDEM_BUILD_TESTS=OFF >/dev/null
cmake --build build-fuzz -j"$(nproc)" --target fuzz_scene fuzz_packing fuzz_checkpoint fuzz_curve fuzz_sweep >/dev/null
corpus=tests/fuzz/corpus
mkdir -p "$corpus"/{scene,packing,checkpoint,curve,sweep}
cp data/scenes/*.toml tests/fuzz/seeds/scene/* "$corpus/scene/"   # seeds/: malformed shapes and --set lines (after %%)
head -c 4000 data/packings/n9261_phi0.70.txt > "$corpus/packing/n9261_head.txt"
printf '##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.003 0.001\n0.005 0.005 0.005 0.001\n' > "$corpus/packing/two.txt"
head -c 6000 data/paper_n9261/D2_phi0.700.csv > "$corpus/curve/d2_head.csv"
# Sweep seeds: the first byte picks the door (even: a table file, odd: a scene with [sweep]).
{ printf '\000'; cat data/powders/adhesion.tsv; } > "$corpus/sweep/adhesion.tsv"
printf '\000name contact.friction\nmu0 0.0\nmu05 0.5\n' > "$corpus/sweep/spaces.txt"
printf '\001[particles]\ncount = 60\n[sweep]\nkeys = ["contact.friction"]\nvalues = [[0.0], [0.5]]\nnames = ["a", "b"]\n' > "$corpus/sweep/scene.toml"
# A small real checkpoint (first byte 1: the target appends the checksum itself).
if [ ! -e "$corpus/checkpoint/seed.ckpt" ]; then
  tmp=$(mktemp -d)
  printf '[particles]\ncount = 60\n[integration]\nthreads = 1\n[protocol]\ncheckpoints_unloading = [0.70]\ncycle_phi_max = 0.72\ncompress_rate_tc = 1e-3\ncycle_rate_tc = 1e-3\nrelax_max_time_tc = 100\nmodes = ["D2"]\n[output]\nvtk = false\n' > "$tmp/s.toml"
  build/dem run "$tmp/s.toml" --out "$tmp/r" --stages prep --quiet >/dev/null 2>&1 || true
  if [ -e "$tmp/r/checkpoints/unloading_phi0.700.ckpt" ]; then
    { printf '\001'; head -c -8 "$tmp/r/checkpoints/unloading_phi0.700.ckpt"; } > "$corpus/checkpoint/seed.ckpt"
  fi
  rm -rf "$tmp"
fi
status=0
for t in scene packing checkpoint curve sweep; do
  mkdir -p "tests/fuzz/findings/$t"
  echo "== fuzz_$t: ${secs} s"
  if ! build-fuzz/tests/fuzz/fuzz_$t "$corpus/$t" -max_total_time="$secs" -rss_limit_mb=2048 -max_len=65536 \
       -artifact_prefix="tests/fuzz/findings/$t/" -print_final_stats=1 2>&1 | grep -E "stat::number_of_executed_units|ERROR|SUMMARY|Done"; then
    :
  fi
  if ls "tests/fuzz/findings/$t"/crash-* "tests/fuzz/findings/$t"/leak-* "tests/fuzz/findings/$t"/timeout-* >/dev/null 2>&1; then
    echo "fuzz_$t: findings in tests/fuzz/findings/$t/"; status=1
  fi
done
exit $status
