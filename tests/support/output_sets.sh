#!/bin/bash
# Outputs that come in sets appear whole or not at all (tsah::AtomicFileSet, docs/bad-inputs.md):
#   output_sets.sh CASE TSAH WORK A.TANIM A.TBVH
# Each case makes one file of a set impossible, interrupts or races the writers, then checks that
# no half of the set (and no staging folder) is left. Exit 0: the promise held.
set -u
case_name=$1 tsah=$2 work=$3 anim=$4 tree=$5
dir="$work/$case_name"
rm -rf "$dir" && mkdir -p "$dir" && cd "$dir" || exit 1

fail() { echo "FAIL: $*"; ls -la "$dir"; exit 1; }
absent() { for f in "$@"; do [ -e "$f" ] && fail "$f was left behind"; done; return 0; }
no_staging() { ls -A | grep -q '^\.tsah-staging' && fail "a staging folder was left behind"; return 0; }
# Runs the command; it must fail with exit 1 and one "tsah: " line matching $1.
expect_error() {
  local pattern=$1; shift
  "$@" >out.txt 2>err.txt
  local rc=$?
  [ "$rc" = 1 ] || fail "exit status $rc, expected 1: $(cat err.txt)"
  [ "$(wc -l <err.txt)" = 1 ] && grep -Eq "^tsah: .*$pattern" err.txt || fail "stderr: $(cat err.txt)"
}
# Waits (at most 10 s) until the writer has staged its set.
wait_staged() {
  for _ in $(seq 100); do ls -A | grep -q '^\.tsah-staging' && return 0; sleep 0.1; done
  fail "the set was never staged"
}

case $case_name in
resample_topology_blocked)  # x.obj cannot be written: x.pc2 must not appear alone
  mkdir x.obj
  expect_error "x.obj: is a folder; expected a file name" "$tsah" resample "$anim" -o x.pc2
  absent x.pc2; no_staging ;;
boxes_obj_blocked)  # b.obj cannot be written: its b.mtl must not appear alone
  mkdir b.obj
  expect_error "b.obj: is a folder; expected a file name" "$tsah" export "$tree" "$anim" --boxes -o b.obj
  absent b.mtl; no_staging ;;
export_buffer_blocked)  # out/woop.bin cannot be written: nodes.bin must not appear alone
  mkdir -p out/woop.bin
  expect_error "woop.bin: is a folder; expected a file name" "$tsah" export "$tree" "$anim" -o out
  absent out/nodes.bin out/tri_index.bin out/tsah_scene.h
  ls -A out | grep -q '^\.tsah-staging' && fail "a staging folder was left in out" ;;
full_disk)  # the file size limit (a full disk for this process) is reached by the second file
  # x.pc2 (2 frames: ~3 KB) fits under 4 KiB, x.obj (~7 KB) does not.
  expect_error "x.obj: write failed after [0-9]+ of [0-9]+ bytes: File too large" \
    bash -c 'ulimit -f 4 && exec "$@"' - "$tsah" resample "$anim" -o x.pc2 --frames 2
  absent x.pc2 x.obj; no_staging ;;
sigterm|sigquit)  # interrupted between staging and commit: nothing of the set appears
  signal=TERM; [ "$case_name" = sigquit ] && signal=QUIT
  ulimit -c 0
  TSAH_TEST_COMMIT_DELAY_MS=20000 "$tsah" resample "$anim" -o x.pc2 >/dev/null 2>&1 &
  pid=$!
  wait_staged
  kill -s $signal $pid
  wait $pid
  rc=$?
  [ $rc -gt 128 ] || fail "exit status $rc: the process was not ended by the signal"
  absent x.pc2 x.obj; no_staging ;;
concurrent)  # two writers of one set: the pair that remains always belongs together
  "$tsah" generate wave -o big.tanim --triangles 20000 --frames 3 >/dev/null || fail "generate"
  for try in 1 2 3 4 5 6 7 8; do
    rm -f x.pc2 x.obj
    "$tsah" resample big.tanim -o x.pc2 >/dev/null 2>big.err &
    big=$!
    "$tsah" resample "$anim" -o x.pc2 >/dev/null 2>small.err &
    small=$!
    wait $big || fail "the first writer failed: $(cat big.err)"
    wait $small || fail "the second writer failed: $(cat small.err)"
    "$tsah" info x.obj+x.pc2 >info.txt 2>&1 || fail "try $try: x.obj and x.pc2 do not match: $(cat info.txt)"
  done
  no_staging ;;
*) fail "unknown case $case_name" ;;
esac
echo "ok: $case_name"
