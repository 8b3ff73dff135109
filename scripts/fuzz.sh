#!/usr/bin/env bash
# Builds every libFuzzer target (clang 14 + libFuzzer + ASan + UBSan, the `fuzz` CMake preset in
# build/fuzz) and runs them one after another, each until it has executed RUNS inputs or spent
# SECONDS, whichever comes first; then writes a summary table (docs/fuzzing.md explains it).
#
#   scripts/fuzz.sh [--runs N] [--seconds S] [--build-only] [TARGET...] [-- LIBFUZZER_OPTION...]
#
# TARGET is an entry of tests/fuzz/entries.hpp (tanim, scene, ...; default: all of them); options
# after -- go to every fuzzer (e.g. -max_len=4096). Seeds come from
# tests/fuzz/corpus/TARGET; what a run learns is kept in build/fuzz/corpus/TARGET and used by the
# next run; crashes, leaks, timeouts and out-of-memory inputs go to build/fuzz/findings/TARGET/.
# Fuzzers run under `nice -n 19`, one at a time (the machine is shared). Exit status 1 when any
# target produced a finding.
set -euo pipefail
cd "$(dirname "$0")/.."

runs=1000000
seconds=600
build_only=0
targets=()
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --runs) runs="$2"; shift 2 ;;
    --seconds) seconds="$2"; shift 2 ;;
    --build-only) build_only=1; shift ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    -*) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
    *) targets+=("$1"); shift ;;
  esac
done
if [ ${#targets[@]} -eq 0 ]; then
  targets=($(sed -n 's/^set(TSAH_FUZZ_ENTRIES \(.*\))$/\1/p' tests/fuzz/CMakeLists.txt))
fi

command -v clang++ >/dev/null || { echo "fuzz.sh: needs clang (apt-get install clang)" >&2; exit 1; }
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
cmake --preset fuzz "${launcher[@]}" >/dev/null
cmake --build build/fuzz -j2 --target $(printf 'fuzz_%s ' "${targets[@]}")
[ "$build_only" = 1 ] && exit 0

export LSAN_OPTIONS="suppressions=$PWD/tests/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
out=build/fuzz
summary=$out/summary.md
{
  echo "# Fuzz run $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo
  echo "Machine: $(nproc) cores, $(sed -n 's/^model name\s*: //p' /proc/cpuinfo | head -1); $(clang++ --version | head -1);"
  echo "budget per target: $runs executions or $seconds s${extra[*]:+; libFuzzer options: ${extra[*]}}; load average at the start: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo
  echo "| target | executions | seconds | exec/s | cov | ft | corpus | peak RSS MB | findings |"
  echo "|---|--:|--:|--:|--:|--:|--:|--:|---|"
} >"$summary"

status=0
for t in "${targets[@]}"; do
  work=$out/corpus/$t findings=$out/findings/$t log=$out/logs/$t.log
  mkdir -p "$work" "$findings" "$(dirname "$log")"
  echo "fuzz.sh: fuzz_$t (log $log)"
  start=$(date +%s)
  set +e
  nice -n 19 "$out/tests/fuzz/fuzz_$t" -runs="$runs" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -print_final_stats=1 -artifact_prefix="$findings/" "${extra[@]}" "$work" "tests/fuzz/corpus/$t" >"$log" 2>&1
  rc=$?
  set -e
  elapsed=$(( $(date +%s) - start ))
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rss=$(sed -n 's/^stat::peak_rss_mb: *//p' "$log" | tail -1)
  last=$(grep -E '^#[0-9]+' "$log" | tail -1)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  corp=$(sed -n 's/.* corp: \([0-9]*\)\/.*/\1/p' <<<"$last")
  found=$(find "$findings" -type f -newermt "@$start" | sed 's|.*/||' | tr '\n' ' ')
  if [ "$rc" != 0 ] || [ -n "$found" ]; then
    status=1
    reason=""
    for pattern in 'what\(\):' 'runtime error:' 'ERROR: (AddressSanitizer|LeakSanitizer|libFuzzer)'; do
      [ -z "$reason" ] && reason=$(grep -m1 -E "$pattern" "$log" | sed 's/^ *//' | cut -c1-200 || true)
    done
    found="exit $rc: ${found:-none written} ${reason:+— ${reason//|/\\|}}"
  fi
  rate=$(( ${execs:-0} / (elapsed > 0 ? elapsed : 1) ))
  echo "| fuzz_$t | ${execs:-?} | $elapsed | $rate | ${cov:-?} | ${ft:-?} | ${corp:-?} | ${rss:-?} | ${found:-none} |" >>"$summary"
done
cat "$summary"
exit $status
