#!/usr/bin/env bash
# Every GPU test binary (release builds, stripped, in .gpu/tests) on the GPU's Vulkan adapter,
# four threads a binary as `cargo test` runs them; each binary at most 150 s.
set -uo pipefail
OUT=${OUT:-target/gpu}; mkdir -p "$OUT"
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json; [ -f "$icd" ] && export VK_DRIVER_FILES=$icd
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
# The tests that run the binary find it by the path it was built at.
mkdir -p target/release && gunzip -c .gpu/firstshot.gz >target/release/firstshot && chmod +x target/release/firstshot
nvidia-smi -L; target/release/firstshot --list-adapters
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
t0=$(date +%s)
for g in .gpu/tests/*.gz; do
    t=$(basename "$g" .gz)
    gunzip -c "$g" >/tmp/t_$t && chmod +x /tmp/t_$t
    a=$(date +%s%N)
    timeout -k 5 150 /tmp/t_$t --test-threads 4 >"$OUT/test_$t.txt" 2>&1
    rc=$?
    echo "$t: exit $rc, $(( ($(date +%s%N) - a) / 1000000 )) ms, $(grep -h '^test result' "$OUT/test_$t.txt" | tail -1)" | tee -a "$OUT/summary.txt"
    [ $(( $(date +%s) - t0 )) -gt 400 ] && { echo "budget spent" | tee -a "$OUT/summary.txt"; break; }
done
cd "$OUT" && tar czf tests.tar.gz test_*.txt && rm -f test_*.txt
