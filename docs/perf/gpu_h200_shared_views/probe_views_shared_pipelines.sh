#!/usr/bin/env bash
# One-off probe after tools/gpu/run.sh: four cameras against one, the build before the
# views shared their pipelines (old) against this one (new), alternated, whole processes.
set -u
gunzip -c .gpu/firstshot_old.gz >/tmp/fs_old; chmod +x /tmp/fs_old
for scene in benches/scenes/cornell_box_4cameras.toml benches/scenes/sierpinski_4cameras.toml; do
  for pair in 1 2 3; do
    for b in old new; do
      fs=target/release/firstshot; [ $b = old ] && fs=/tmp/fs_old
      for mode in one all; do
        flag=""; [ $mode = all ] && flag=--all-cameras
        a=$(date +%s%N)
        timeout 60 $fs $scene $flag --adapter vulkan --iterations 1000 --width 256 --height 256 --out /tmp/v --quiet --stats /tmp/v.json
        echo "$(basename $scene .toml) 1000 steps pair $pair $b $mode $((($(date +%s%N) - a) / 1000000)) ms, total_ms $(python3 -c "import json;print(round(json.load(open('/tmp/v.json'))['total_ms']))")"
      done
    done
  done
done
