# Session 2026-11-30 16:30 UTC: the sky by each pixel's own ray on an H200 (fused gather), then
# the test binaries of .gpu/tests (tools/gpu/tests.sh).
set -uo pipefail
OUT=${OUT:-target/gpu}; mkdir -p "$OUT"
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json; [ -f "$icd" ] && export VK_DRIVER_FILES=$icd
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"; fi
mkdir -p target/release && gunzip -c .gpu/firstshot.gz >target/release/firstshot && chmod +x target/release/firstshot
gunzip -c .gpu/harness.gz >/tmp/harness && chmod +x /tmp/harness
fs=target/release/firstshot
for g in fused split fused split; do
    a=$(date +%s%N)
    timeout 60 $fs benches/scenes/sky_gallery.toml --adapter vulkan --gather $g --iterations 500 --seed 1 --out /tmp/sky_$g.exr --stats /tmp/sky_$g.json --quiet
    echo "sky_gallery --gather $g: exit $?, $((($(date +%s%N) - a) / 1000000)) ms, $(grep -o '"iteration_ms_median": [0-9.]*' /tmp/sky_$g.json)"
done
$fs compare /tmp/sky_fused.exr /tmp/sky_split.exr
timeout 60 /tmp/harness --bench throughput --adapters 0 --repeats 3 --steps 200 --scenes benches/scenes/sky_gallery.toml --out $OUT/tp_sky 2>&1 | grep -v "^$" | head -32
bash tools/gpu/tests.sh 150
