#!/usr/bin/env bash
# One-off GPU check of this session's shader changes (the sun's crease and outline rules):
# the lights, per_pixel and views integration tests on the GPU's Vulkan adapter, and
# sun_room at 1000 steps against the Mitsuba reference made on the CPU.
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
mkdir -p target/release /tmp/t
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
for t in lights per_pixel views; do gunzip -c .gpu/tests/$t.gz >/tmp/t/$t; chmod +x /tmp/t/$t; done
nvidia-smi -L
target/release/firstshot --list-adapters
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
for t in lights per_pixel views; do
  echo "== $t"; timeout 150 /tmp/t/$t --test-threads 4 2>&1 | grep -E "^test |test result|panicked|GPU test on" | sort | uniq -c | sort -rn | head -40
done
echo "== sun_room"
for i in 1 2; do
  timeout 60 target/release/firstshot scenes/sun_room.toml --adapter vulkan --iterations 1000 --width 256 --height 256 --seed $i --quiet --out /tmp/sun$i --stats /tmp/sun$i.json
  target/release/firstshot compare /tmp/sun$i.exr .gpu/ref_sun_room.exr | head -2
  python3 -c "import json;d=json.load(open('/tmp/sun$i.json'));print('total_ms', round(d['total_ms']), 'steps/s', round(1000*1000/d['iteration_ms']))"
done
