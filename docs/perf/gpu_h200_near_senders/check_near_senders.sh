#!/usr/bin/env bash
# GPU check of the near senders' first bounce per point and the lines beside at creases:
# the lights, per_pixel, views and emitters integration tests on the GPU's Vulkan adapter,
# and sun_room at 1000 steps against the Mitsuba reference made on the CPU.
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
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
for t in per_pixel views; do
  echo "== $t"; a=$(date +%s)
  timeout 100 /tmp/t/$t --test-threads 4 2>&1 | grep -E "^test |test result|panicked|GPU test on" | sort | uniq -c | sort -rn | head -40
  echo "$t: $(( $(date +%s) - a )) s"
done
echo "== sun_room"
for i in 1 2; do
  for mode in point patch; do
    flag=""; [ $mode = patch ] && flag=--patch-first-bounce
    timeout 60 target/release/firstshot scenes/sun_room.toml $flag --adapter vulkan --iterations 1000 --width 256 --height 256 --seed $i --quiet --out /tmp/sun$i$mode --stats /tmp/sun$i$mode.json
    echo "seed $i $mode: $(target/release/firstshot compare /tmp/sun$i$mode.exr .gpu/ref_sun_room.exr | head -2 | tr '\n' ' ')"
    python3 -c "import json;d=json.load(open('/tmp/sun$i$mode.json'));print('  total_ms', round(d['total_ms']))"
  done
done
for s in cornell_box cornell_point; do for mode in point patch; do
  flag=""; [ $mode = patch ] && flag=--patch-first-bounce
  timeout 60 target/release/firstshot scenes/$s.toml $flag --adapter vulkan --iterations 2000 --width 256 --height 256 --quiet --out /tmp/$s$mode
  echo "$s 2000 $mode: $(target/release/firstshot compare /tmp/$s$mode.exr .gpu/${s}256.exr | head -1)"
done; done
