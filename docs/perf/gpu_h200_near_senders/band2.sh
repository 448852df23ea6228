#!/usr/bin/env bash
# The umbra leak beside the tall block: the direct-light image at 512 x 512 with finer
# windows, smaller patches and a point light's exactness check.
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
mkdir -p target/release $OUT
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
run() { name=$1; shift; timeout 100 target/release/firstshot scenes/cornell_box.toml "$@" --adapter vulkan --iterations 0 --direct-passes 1024 --seed 2 --width 512 --height 512 --quiet --out $OUT/$name --stats $OUT/$name.json; rm -f $OUT/*.png; }
run auto
run s1024 --shadow-resolution 1024
run s2048 --shadow-resolution 2048
run s4096 --shadow-resolution 4096
run p10 --patch-size 10
ls -la $OUT
