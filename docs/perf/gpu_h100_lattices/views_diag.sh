#!/usr/bin/env bash
# Why the views tests ran past 100 s on an H100 (5 s on an H200): the suite under a
# watchdog that prints the stuck processes, then each test not reported ok, alone.
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
mkdir -p target/release /tmp/t
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
gunzip -c .gpu/tests/views.gz >/tmp/t/views; chmod +x /tmp/t/views
nvidia-smi -L
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
watch() {
  sleep $1
  echo "== watchdog at $1 s"
  ps -eo pid,ppid,etimes,stat,wchan:32,args | grep -E "firstshot|views" | grep -v grep
  for p in $(pgrep -f target/release/firstshot); do
    echo "-- $p threads:"; for t in /proc/$p/task/*; do echo "  $(cat $t/comm) $(cat $t/wchan) $(cat $t/stat | cut -d' ' -f3)"; done
    cat /proc/$p/stack 2>/dev/null | head -8
  done
}
a=$(date +%s)
watch 40 & w=$!
timeout 45 /tmp/t/views --test-threads 4 --nocapture >$OUT/views_suite.txt 2>&1; echo "suite exit $? in $(( $(date +%s) - a )) s"
kill $w 2>/dev/null; wait $w 2>/dev/null
grep -E "^test |test result" $OUT/views_suite.txt
for t in $(/tmp/t/views --list 2>/dev/null | grep ': test' | cut -d: -f1); do
  grep -q "^test $t ... ok" $OUT/views_suite.txt && continue
  a=$(date +%s); watch 15 & w=$!
  timeout 20 /tmp/t/views --exact $t --nocapture >$OUT/$t.txt 2>&1; echo "$t exit $? in $(( $(date +%s) - a )) s"
  kill $w 2>/dev/null; wait $w 2>/dev/null
  tail -5 $OUT/$t.txt
done
tail -30 $OUT/views_suite.txt
