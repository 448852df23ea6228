#!/usr/bin/env bash
# Is the Cornell boxes' bright block foot the patches' or the gather's? The same 16000 steps
# at half and a quarter of the patch size (seed 1), saved for their error maps.
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
mkdir -p target/release /tmp/f $OUT/f
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
fs=target/release/firstshot
for s in cornell_box cornell_point; do
  for p in 20 10; do
    a=$(date +%s%N)
    timeout 150 $fs scenes/$s.toml --patch-size $p --adapter vulkan --iterations 16000 --width 256 --height 256 --seed 1 --quiet --out $OUT/f/${s}_p${p} --stats /tmp/f/${s}_p$p.json
    b=$(date +%s%N)
    echo "$s patch $p: $($fs compare $OUT/f/${s}_p${p}.exr .gpu/${s}256.exr | head -2 | tr -s ' ' | tr '\n' ' ') [$(( (b - a) / 1000000 )) ms] $(grep -o '"patches":[0-9]*' /tmp/f/${s}_p$p.json) $(grep -o '"bundle_resolution":[0-9]*' /tmp/f/${s}_p$p.json)"
    rm -f $OUT/f/*.png
  done
done
