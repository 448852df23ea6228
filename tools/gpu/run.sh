#!/usr/bin/env bash
# The GPU side of the benchmark harness, in one command on a machine with an NVIDIA GPU
# and nothing else installed (the device machines this project is sometimes lent), from
# the repository root, after tools/gpu/prepare.sh on an x86-64 build machine:
#
#   bash tools/gpu/run.sh [SECONDS]        (SECONDS: the whole run's budget, default 480)
#
# Every stage has its own time limit, so a hang or a slow stage costs only its share and the
# stages after it still run. Everything lands in $OUT (default target/gpu): gpu.tar.gz with
# the harness's JSON/SVG and the logs, and log.txt. Stages:
#   1. the Vulkan loader (.gl), Mitsuba for the machine's python3 (.whl), the builds (.gpu)
#   2. smoke: adapters, one firstshot render, one Mitsuba cuda_ad_rgb render
#   3. peers: time to 10/5/2 % error, firstshot on the GPU's Vulkan adapter against
#      Mitsuba cuda_ad_rgb, one harness run per scene (partial results survive a timeout)
#   4. throughput: stage timestamps, Sierpinski at bundle 512 and the Cornell box
#   5. views: --all-cameras with four cameras against one camera, alternated, the gather
#      fused (the GPU's default) and split
#   6. scaling: memory and time up to millions of patches and 8K images
#   7. windows: Sierpinski's stage profile with the area light's windows instead of shadow
#      rays (--light-visibility windows), against stage 4's, if the budget leaves time
# FIRSTSHOT_GPU_STAGES="peers views" runs only those (by name or by prefix: peers_sierpinski).
set -uo pipefail
budget=${1:-480}
OUT=${OUT:-target/gpu}
mkdir -p "$OUT"
work=$(mktemp -d /tmp/firstshot-gpu.XXXX)
t0=$(date +%s)
log() { echo "[$(($(date +%s) - t0)) s] $*" | tee -a "$work/log.txt"; }
left() { echo $((budget - ($(date +%s) - t0))); }
# `stage NAME SECONDS CMD...`: runs CMD with at most SECONDS (less if the budget is short).
stage() {
    local name=$1 limit=$2; shift 2
    case " ${FIRSTSHOT_GPU_STAGES:-$name} " in *" ${name%%_*} "* | *" $name "*) ;; *) return 0 ;; esac
    local l; l=$(left); [ "$l" -lt "$limit" ] && limit=$l
    if [ "$limit" -le 5 ]; then log "skip $name: budget spent"; return 1; fi
    log "begin $name (limit $limit s)"
    timeout -k 5 "$limit" "$@" >"$work/$name.log" 2>&1
    local rc=$?
    log "end $name: exit $rc"
    tail -n 40 "$work/$name.log"
    return $rc
}
finish() {
    cp "$work/log.txt" "$OUT/log.txt"
    sleep 1; tar czf "$OUT/gpu.tar.gz" --warning=no-file-changed --exclude="*.exr" --exclude="*.png" --exclude="*.part" -C "$work" .
    log "results: $OUT/gpu.tar.gz"
}
trap finish EXIT

# 1. Set-up.
if [ "${FIRSTSHOT_GPU_DRY_RUN:-0}" != 1 ]; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    [ -f "$icd" ] && export VK_DRIVER_FILES=$icd
    egl=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    [ -f "$egl" ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$egl
    mkdir -p /tmp/site && tar xzf .whl/site.tar.gz -C /tmp/site
    export PYTHONPATH=/tmp/site FIRSTSHOT_PYTHON=python3
fi
# The builds name the repository by the path they were built in (the harness finds
# firstshot, refs/ and tools/ there): the same path leads here.
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
mkdir -p target/release
gunzip -c .gpu/firstshot.gz >target/release/firstshot
gunzip -c .gpu/harness.gz >.gpu/harness
chmod +x target/release/firstshot .gpu/harness
fs=target/release/firstshot
harness=".gpu/harness --bench"
py=${FIRSTSHOT_PYTHON:-python3}
{ nvidia-smi -L; nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.sm,clocks.max.sm --format=csv; nproc; } \
    >"$work/machine.txt" 2>&1
cat "$work/machine.txt"

# 2. Smoke.
timeout 30 $fs --list-adapters >"$work/adapters.txt" 2>/dev/null
cat "$work/adapters.txt"
# The GPU's Vulkan adapter, by its position in the list (the harness's --adapters takes it).
# FIRSTSHOT_GPU_DRY_RUN=1 takes the CPU's instead, to try this script on a machine without
# a GPU (with .venv's Mitsuba and its llvm variant; the set-up of stage 1 is skipped).
kind='!= "Cpu"'; variant=cuda_ad_rgb
if [ "${FIRSTSHOT_GPU_DRY_RUN:-0}" = 1 ]; then
    kind='== "Cpu"' variant=llvm_ad_rgb
    export FIRSTSHOT_PYTHON=${FIRSTSHOT_PYTHON:-.venv/bin/python}
    py=$FIRSTSHOT_PYTHON
fi
vk=$(awk -F'\t' "\$2 == \"Vulkan\" && \$3 $kind { print NR - 1; exit }" "$work/adapters.txt")
[ -n "$vk" ] || { log "no Vulkan GPU adapter: see adapters.log"; exit 1; }
log "Vulkan GPU adapter: index $vk"
stage smoke_firstshot 60 $fs scenes/cornell_box.toml --adapter vulkan --iterations 200 \
    --out "$work/smoke_cb" --stats "$work/smoke_cb.json" || exit 1
stage smoke_mitsuba 90 $py tools/mitsuba/render.py scenes/cornell_box.toml --variant $variant --spp 64 \
    --width 256 --height 256 --out "$work/smoke_mitsuba.exr" && mitsuba_ok=1 || mitsuba_ok=0
stage smoke_compare 20 $fs compare "$work/smoke_cb.exr" refs/cornell_box.full.exr

# 3. Peers, a scene at a time. The GPU reaches the smaller errors quickly: one budget more each.
steps=2,5,10,20,50,100,200,500,1000,2000
spp=1,2,4,8,16,32,64,128,256,512,1024,2048
for s in cornell_box cornell_point sierpinski; do
    [ $mitsuba_ok = 1 ] || break
    # refs/ holds the Cornell boxes' references; Sierpinski's comes with .gpu (a lone
    # --reference would be taken for any single scene).
    ref=(); [ $s = sierpinski ] && [ -f .gpu/sierpinski.full.exr ] && ref=(--reference .gpu/sierpinski.full.exr)
    stage "peers_$s" 110 $harness peers --adapters $vk --scenes $s "${ref[@]}" \
        --peer-steps $steps --peer-spp $spp --out "$work/peers_$s"
done

# 4. Throughput with GPU timestamps. The steps/s target (docs/PERFORMANCE.md, Targets) is one
# bundle of 512 a step; at Sierpinski's own 512 x 512 the automatic count is four.
stage throughput_sierpinski512 60 $harness throughput --adapters $vk --repeats 5 --steps 200 \
    --scenes sierpinski --bundle-resolution 512 --bundles-per-step 1 --out "$work/throughput_sierpinski512"
stage throughput 60 $harness throughput --adapters $vk --repeats 5 --steps 200 \
    --scenes sierpinski,cornell_box,cornell_point --out "$work/throughput"

# 5. Views: one camera against four, alternated, 256 x 256, same steps; each pair with the
# gather as the adapter gets it (fused on a GPU) and split (`--gather split`), alternated too.
views() {
    for scene in benches/scenes/sierpinski_4cameras.toml benches/scenes/cornell_box_4cameras.toml; do
        for steps in 200 1000; do
            for pair in 1 2 3; do
                for gather in auto split; do
                    for mode in one all; do
                        flag=""; [ $mode = all ] && flag=--all-cameras
                        a=$(date +%s%N)
                        $fs $scene $flag --gather $gather --adapter vulkan --iterations $steps --width 256 \
                            --height 256 --out "$work/views_$mode" --stats "$work/views_$mode.json" --quiet || return 1
                        b=$(date +%s%N)
                        step=$(grep -o '"iteration_ms_median": [0-9.]*' "$work/views_$mode.json" | cut -d' ' -f2)
                        used=$(grep -o '"gather": "[a-z]*"' "$work/views_$mode.json" | cut -d'"' -f4)
                        echo "$(basename $scene .toml) steps $steps pair $pair gather $used $mode" \
                            "$(((b - a) / 1000000)) ms, median step $step ms"
                    done
                done
            done
        done
    done
}
export -f views; export fs work
stage views 150 bash -c views

# 6. Scaling: GPU memory and step time from 22 k to millions of patches, images to 8K.
# FIRSTSHOT_GPU_PATCH_SIZES / _IMAGES / _SCALING_LIMIT take it further (0.003: some 80 M patches).
stage scaling "${FIRSTSHOT_GPU_SCALING_LIMIT:-120}" $harness scaling --adapters $vk --repeats 1 \
    --patch-sizes "${FIRSTSHOT_GPU_PATCH_SIZES:-0.35,0.1,0.03,0.015,0.0085}" \
    --images "${FIRSTSHOT_GPU_IMAGES:-512x512,2048x2048,7680x4320}" --out "$work/scaling"

# 7. The area light's visibility by windows, for the shadow rays' side by side (stage 4 has
# the rays, the default).
stage windows 40 $harness throughput --adapters $vk --repeats 3 --steps 200 --scenes sierpinski \
    --light-visibility windows --out "$work/throughput_windows"
log "done"
