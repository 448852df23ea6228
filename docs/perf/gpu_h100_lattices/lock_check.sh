#!/usr/bin/env bash
# The driver lock (src/gpu/context.rs) on an H100: the views suite on four threads three
# times (it hung every time before), and hardening test18 (eight threads open devices).
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
root=$(cat .gpu/manifest_dir)
if [ "$(realpath "$root" 2>/dev/null)" != "$(realpath .)" ]; then
    mkdir -p "$(dirname "$root")" && rm -rf "$root" && ln -s "$(realpath .)" "$root"
fi
mkdir -p target/release /tmp/t
gunzip -c .gpu/firstshot.gz >target/release/firstshot; chmod +x target/release/firstshot
for t in views hardening; do gunzip -c .gpu/tests/$t.gz >/tmp/t/$t; chmod +x /tmp/t/$t; done
nvidia-smi -L
export FIRSTSHOT_REQUIRE_GPU=1 FIRSTSHOT_REQUIRE_BACKEND=vulkan
for i in 1 2 3; do
  a=$(date +%s%N); timeout 25 /tmp/t/views --test-threads 4 >$OUT/views_$i.txt 2>&1; rc=$?
  echo "views suite run $i: exit $rc in $(( ($(date +%s%N) - a) / 1000000 )) ms; $(grep 'test result' $OUT/views_$i.txt)"
done
a=$(date +%s%N); timeout 40 /tmp/t/hardening --exact test18_threads_open_and_close_devices_at_once >$OUT/test18.txt 2>&1; rc=$?
echo "hardening test18: exit $rc in $(( ($(date +%s%N) - a) / 1000000 )) ms; $(grep 'test result' $OUT/test18.txt)"
