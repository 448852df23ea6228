#!/usr/bin/env bash
# The GPU tests on a machine with an NVIDIA GPU and nothing else installed, from the
# repository root, after `FIRSTSHOT_GPU_TESTS=1 tools/gpu/prepare.sh` on an x86-64 build
# machine (carry .gl and .gpu; .whl is not needed):
#
#   bash tools/gpu/tests.sh [SECONDS]      (SECONDS: the whole run's budget, default 400)
#
# Each test binary of .gpu/tests runs on four threads, as `cargo test` runs it, with at most
# 150 s, on the GPU's Vulkan adapter (FIRSTSHOT_REQUIRE_GPU=1, FIRSTSHOT_REQUIRE_BACKEND=
# vulkan, as CI asks of lavapipe). One line a binary lands in $OUT/summary.txt (default
# target/gpu), the outputs in $OUT/tests.tar.gz. Exit status 1 if any binary failed.
set -uo pipefail
budget=${1:-400}
OUT=${OUT:-target/gpu}
mkdir -p "$OUT"
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f "$icd" ] && export VK_DRIVER_FILES=$icd
# The builds name the repository by the path they were built in (the tests read scenes/ and
# refs/ there): the same path leads here.
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
# The tests that run the binary find it at target/release/firstshot of that path.
mkdir -p target/release
gunzip -c .gpu/firstshot.gz >target/release/firstshot && chmod +x target/release/firstshot
{ nvidia-smi -L; target/release/firstshot --list-adapters; } 2>&1 | tee "$OUT/machine.txt"
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
work=$(mktemp -d /tmp/firstshot-gpu-tests.XXXX)
t0=$(date +%s)
failed=0
: >"$OUT/summary.txt"
for g in .gpu/tests/*.gz; do
    if [ $(($(date +%s) - t0)) -gt "$budget" ]; then
        echo "budget of $budget s spent: $(basename "$g" .gz) and after not run" | tee -a "$OUT/summary.txt"
        failed=1
        break
    fi
    t=$(basename "$g" .gz)
    gunzip -c "$g" >"$work/$t" && chmod +x "$work/$t"
    a=$(date +%s%N)
    timeout -k 5 150 "$work/$t" --test-threads 4 >"$work/test_$t.txt" 2>&1
    rc=$?
    [ $rc = 0 ] || failed=1
    echo "$t: exit $rc, $((($(date +%s%N) - a) / 1000000)) ms, $(grep -h '^test result' "$work/test_$t.txt" | tail -1)" |
        tee -a "$OUT/summary.txt"
done
tar czf "$OUT/tests.tar.gz" -C "$work" $(cd "$work" && ls test_*.txt)
exit $failed
