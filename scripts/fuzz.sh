#!/bin/sh
# Builds the libFuzzer targets (tests/fuzz) with clang in build/fuzz and runs each for
# SECONDS (default 60), starting from the seed corpus in tests/fuzz/corpus/<target>.
# Exits non-zero when any target finds a crash, a leak, a timeout or an out-of-memory;
# the reproducer is left in build/fuzz/findings/<target>/ (keep it in tests/fuzz/regressions/).
#
#   scripts/fuzz.sh [SECONDS] [pfm|exr|detector|buffers|accumulator ...]
#
# Installs clang and libFuzzer with apt-get when they are missing (needs root).
set -eu
cd "$(dirname "$0")/.."
secs=${1:-60}
[ $# -gt 0 ] && shift
targets=${*:-"pfm exr detector buffers accumulator"}
build=build/fuzz

have_libfuzzer() {
  command -v clang++ >/dev/null 2>&1 || return 1
  printf 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }\n' |
    clang++ -x c++ -fsanitize=fuzzer,address,undefined - -o /tmp/firefly-fuzz-probe.$$ >/dev/null 2>&1
  ok=$?
  rm -f /tmp/firefly-fuzz-probe.$$
  return $ok
}
if ! have_libfuzzer; then
  if [ "$(id -u)" != 0 ]; then
    echo "fuzz.sh: clang with libFuzzer is missing; as root: apt-get install clang libfuzzer-14-dev libclang-rt-14-dev" >&2
    exit 2
  fi
  apt-get update -qq && apt-get install -y -qq clang libfuzzer-14-dev libclang-rt-14-dev >/dev/null
fi

cmake -S . -B "$build" -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DFIREFLY_BUILD_FUZZERS=ON -DFIREFLY_BUILD_BENCHMARKS=OFF -DFIREFLY_BUILD_EXAMPLES=OFF >/dev/null
status=0
for t in $targets; do
  if ! cmake --build "$build" -j2 --target "fuzz_$t" >"$build/fuzz_$t.build.log" 2>&1; then
    echo "fuzz.sh: fuzz_$t does not build (see $build/fuzz_$t.build.log)" >&2
    status=1
    continue
  fi
  exe=$(find "$build" -name "fuzz_$t" -type f -perm -u+x | head -n 1)
  work="$build/corpus/$t"
  findings="$build/findings/$t"
  mkdir -p "$work" "$findings"
  # Saved reproducers first: a fixed bug must stay fixed.
  if ! "$exe" -runs=0 tests/fuzz/regressions/$t >"$build/fuzz_$t.replay.log" 2>&1; then
    echo "fuzz_$t: a saved reproducer fails again (see $build/fuzz_$t.replay.log)" >&2
    status=1
  fi
  echo "fuzz_$t: $secs s"
  if "$exe" "$work" "tests/fuzz/corpus/$t" -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=256 \
       -artifact_prefix="$findings/" -print_final_stats=1 >"$build/fuzz_$t.log" 2>&1; then
    grep -E "stat::number_of_executed_units|cov: " "$build/fuzz_$t.log" | tail -n 2
  else
    echo "fuzz_$t: FINDING (log: $build/fuzz_$t.log, reproducer in $findings/)" >&2
    grep -E "^==[0-9]+==ERROR|runtime error|fuzz_[a-z]+:|SUMMARY" "$build/fuzz_$t.log" | head -n 5 >&2
    status=1
  fi
done
exit $status
