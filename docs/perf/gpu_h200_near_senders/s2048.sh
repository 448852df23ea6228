#!/usr/bin/env bash
# The Cornell box with every window face at 2048 against the automatic sides: error at 16000
# steps, and the time of 1000 steps (whole processes, alternated).
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
mkdir -p target/release /tmp/f
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
fs=target/release/firstshot
for s in cornell_box cornell_point; do
  for opt in "" "--shadow-resolution 2048"; do
    timeout 100 $fs scenes/$s.toml $opt --adapter vulkan --iterations 16000 --width 256 --height 256 --seed 1 --quiet --out /tmp/f/x
    echo "$s 16000 [$opt]: $($fs compare /tmp/f/x.exr .gpu/${s}256.exr | head -2 | tr -s ' ' | tr '\n' ' ')"
  done
done
for pair in 1 2 3; do
  for opt in "" "--shadow-resolution 2048"; do
    a=$(date +%s%N)
    $fs scenes/cornell_box.toml $opt --adapter vulkan --iterations 1000 --width 256 --height 256 --seed 1 --quiet --out /tmp/f/y
    b=$(date +%s%N)
    echo "cornell_box 1000 steps [$opt] pair $pair: $(( (b - a) / 1000000 )) ms"
  done
done
