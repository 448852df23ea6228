#!/usr/bin/env bash
# Is the bright floor at the short block's foot the plane rule's Lbar_j? The same 4000 steps
# with that fallback answering black (a throw-away build, fs_black).
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
mkdir -p target/release $OUT/f
gunzip -c .gpu/firstshot.gz >target/release/firstshot; gunzip -c .gpu/fs_black.gz >target/release/fs_black; chmod +x target/release/*
for s in cornell_box cornell_point; do
  for b in firstshot fs_black; do
    timeout 100 target/release/$b scenes/$s.toml --adapter vulkan --iterations 8000 --width 256 --height 256 --seed 1 --quiet --out $OUT/f/${s}_$b
    echo "$s $b: $(target/release/firstshot compare $OUT/f/${s}_$b.exr .gpu/${s}256.exr | head -2 | tr -s ' ' | tr '\n' ' ')"
    rm -f $OUT/f/*.png
  done
done
