#!/usr/bin/env bash
# Fifth GPU run (2026-11-27): the per_pixel and views tests on the GPU's Vulkan adapter,
# 2000-step errors of the Cornell boxes and 1000 of sun_room, then the whole harness side.
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
mkdir -p target/release /tmp/t
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
for t in per_pixel views; do gunzip -c .gpu/tests/$t.gz >/tmp/t/$t; chmod +x /tmp/t/$t; done
nvidia-smi -L
(
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
for t in per_pixel views; do
  echo "== $t"; a=$(date +%s)
  timeout 100 /tmp/t/$t --test-threads 4 2>&1 | grep -E "^test |test result|panicked|GPU test on" | sort | uniq -c | sort -rn | head -40
  echo "$t: $(( $(date +%s) - a )) s"
done
for s in cornell_box cornell_point; do
  timeout 60 target/release/firstshot scenes/$s.toml --adapter vulkan --iterations 2000 --width 256 --height 256 --quiet --out /tmp/$s --stats /tmp/$s.json
  echo "$s 2000: $(target/release/firstshot compare /tmp/$s.exr .gpu/${s}256.exr | head -1) total_ms $(python3 -c "import json;print(round(json.load(open('/tmp/$s.json'))['total_ms']))")"
done
timeout 60 target/release/firstshot scenes/sun_room.toml --adapter vulkan --iterations 1000 --width 256 --height 256 --seed 1 --quiet --out /tmp/sun
echo "sun_room 1000 seed 1: $(target/release/firstshot compare /tmp/sun.exr .gpu/ref_sun_room.exr | head -1)"
) 2>&1 | tee $OUT/check5.txt
FIRSTSHOT_GPU_STAGES="smoke peers throughput views scaling" bash tools/gpu/run.sh 330
