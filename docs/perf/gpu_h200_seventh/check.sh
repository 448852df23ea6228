set -uo pipefail
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json; [ -f "$icd" ] && export VK_DRIVER_FILES=$icd
root=$(cat .gpuD/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"; fi
for b in per_pixel harness firstshot; do gunzip -c .gpuD/$b.gz >/tmp/$b && chmod +x /tmp/$b; done
mkdir -p target/release && cp /tmp/firstshot target/release/firstshot
nvidia-smi --query-gpu=name,driver_version,clocks.sm --format=csv
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
a=$(date +%s%N); timeout -k 5 120 /tmp/per_pixel --test-threads 4 >$OUT/test_per_pixel.txt 2>&1
echo "per_pixel: exit $?, $((($(date +%s%N) - a) / 1000000)) ms, $(grep '^test result' $OUT/test_per_pixel.txt)"
grep "view 0\|view 1\|view 2\|view 3" $OUT/test_per_pixel.txt
unset FIRSTSHOT_REQUIRE_GPU FIRSTSHOT_REQUIRE_BACKEND
timeout -k 5 90 /tmp/harness --bench throughput --adapters 0 --repeats 5 --steps 200 --scenes sierpinski --bundle-resolution 512 --bundles-per-step 1 --out $OUT/tp1 2>&1 | grep -v "^$" | head -30
