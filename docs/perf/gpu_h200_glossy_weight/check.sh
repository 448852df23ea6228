#!/usr/bin/env bash
# Session 2026-11-27 evening: the per_pixel and views tests on the GPU's Vulkan adapter, then
# the GPU side of the harness (tools/gpu/run.sh).
set -uo pipefail
OUT=${OUT:-target/gpu}; mkdir -p "$OUT"
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json; [ -f "$icd" ] && export VK_DRIVER_FILES=$icd
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
# The views tests run the firstshot binary (by the path it was built at): unpack it first.
mkdir -p target/release && gunzip -c .gpu/firstshot.gz >target/release/firstshot && chmod +x target/release/firstshot
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
for t in per_pixel views; do
    gunzip -c .gpu/$t.gz >/tmp/$t && chmod +x /tmp/$t
    a=$(date +%s%N)
    timeout -k 5 90 /tmp/$t --test-threads 4 >"$OUT/test_$t.txt" 2>&1
    echo "test $t: exit $? in $(( ($(date +%s%N) - a) / 1000000 )) ms"; tail -n 3 "$OUT/test_$t.txt"
done
bash tools/gpu/run.sh "${1:-400}"
