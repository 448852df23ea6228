#!/usr/bin/env bash
# Upload before (one thread) and after (every core), alternated, on the GPU's Vulkan adapter.
set -uo pipefail
OUT=${OUT:-target/gpu}; mkdir -p "$OUT"
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json; [ -f "$icd" ] && export VK_DRIVER_FILES=$icd
for b in firstshot fs_base; do gunzip -c .gpu/$b.gz >/tmp/$b && chmod +x /tmp/$b; done
nproc; nvidia-smi -L
for ps in 0.015 0.0085; do for pair in 1 2; do for b in fs_base firstshot; do
    /tmp/$b scenes/sierpinski.toml --adapter vulkan --patch-size $ps --iterations 2 --burn-in 0 --width 128 --height 128 \
        --out /tmp/u.exr --stats /tmp/u.json --quiet || echo "$b failed"
    python3 -c "
import json; s=json.load(open('/tmp/u.json'))
print('$ps', '$pair', '$b', s['patches'], 'tess', round(s['tessellation_ms']), 'upload', round(s['upload_ms']), 'first_shot', round(s['first_shot_ms']), 'total', round(s['total_ms']), 'peak MiB', round(s['memory']['peak_rss_bytes']/2**20))" | tee -a $OUT/upload.txt
done; done; done
