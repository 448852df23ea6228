#!/usr/bin/env bash
# Where the error stops falling: the bundled scenes at 1000 / 4000 / 16000 steps on the GPU,
# two seeds each, against the references (and the two seeds against each other: their
# difference is sqrt(2) times one image's noise).
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
mkdir -p target/release /tmp/f
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
fs=target/release/firstshot
nvidia-smi -L
for s in cornell_box cornell_point sierpinski; do
  ref=.gpu/${s}256.exr; [ $s = sierpinski ] && ref=.gpu/sierpinski.full.exr
  for n in 1000 4000 16000; do
    for seed in 1 2; do
      a=$(date +%s%N)
      timeout 90 $fs scenes/$s.toml --adapter vulkan --iterations $n --width 256 --height 256 --seed $seed --quiet --out /tmp/f/${s}_${n}_$seed
      b=$(date +%s%N)
      echo "$s $n seed $seed: $($fs compare /tmp/f/${s}_${n}_$seed.exr $ref | head -2 | tr -s ' ' | tr '\n' ' ') [$(( (b - a) / 1000000 )) ms]"
    done
    echo "$s $n seed 1 vs seed 2: $($fs compare /tmp/f/${s}_${n}_1.exr /tmp/f/${s}_${n}_2.exr | head -1 | tr -s ' ')"
  done
done
for seed in 1 2; do
  timeout 90 $fs scenes/cornell_box.toml --patch-first-bounce --adapter vulkan --iterations 16000 --width 256 --height 256 --seed $seed --quiet --out /tmp/f/cbp_$seed
  echo "cornell_box 16000 --patch-first-bounce seed $seed: $($fs compare /tmp/f/cbp_$seed.exr .gpu/cornell_box256.exr | head -2 | tr -s ' ' | tr '\n' ' ')"
done
mkdir -p $OUT/f && cp /tmp/f/*_16000_1.exr $OUT/f/ 2>/dev/null
