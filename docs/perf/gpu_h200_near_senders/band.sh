#!/usr/bin/env bash
# The tall block's lit band on the GPU: the direct-light image at 512 x 512.
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
mkdir -p target/release $OUT
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
for passes in 256 4096; do
  timeout 100 target/release/firstshot scenes/cornell_box.toml --adapter vulkan --iterations 0 --direct-passes $passes --seed 2 --width 512 --height 512 --quiet --out $OUT/cbd512_$passes
  rm -f $OUT/*.png
done
ls -la $OUT
