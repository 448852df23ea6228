#!/usr/bin/env bash
# Prepares, on this (x86-64) machine, what the GPU side of the benchmark harness needs on a
# machine with an NVIDIA GPU and no package registry (the device machines this project is
# sometimes lent): tools/gpu/run.sh runs there and reads only what this script leaves in
# three git-ignored folders of the repository:
#
#   .gl/   the Vulkan loader and GL dispatch libraries (Debian .deb files, unpacked there)
#   .whl/  Mitsuba 3 and Dr.Jit for the machine's Python (3.12), trimmed to the cuda_ad_rgb
#          and scalar_rgb variants and the plugins tools/mitsuba/convert.py uses, so that the
#          whole tree stays under the 64 MiB a call may carry
#   .gpu/  stripped, gzipped release builds of `firstshot` and the harness
#
# Usage (repository root):  [FIRSTSHOT_SIERPINSKI_REFERENCE=ref.exr] tools/gpu/prepare.sh
# Then the study runs in one call of the device tool, carrying .gl, .whl and .gpu:
#   bash tools/gpu/run.sh            (docs/PERFORMANCE.md, "On a GPU")
#
# FIRSTSHOT_GPU_TESTS=1 tools/gpu/prepare.sh also packs the GPU tests' binaries into
# .gpu/tests/ (stripped and gzipped, about 3 MB each), for `bash tools/gpu/tests.sh` there:
# the test suite on the GPU's own driver, which lavapipe's CI cannot be (races, a driver's
# limits and capabilities). The library's unit tests are `firstshot_lib`, the command line's
# `firstshot`. FIRSTSHOT_GPU_TESTS="cli views" packs only those. All 22 come to about 60 MB,
# more than a call of the device tool carries beside the builds and the tracked files (64
# MiB, .whl left behind: the tests do not need it), so pack them in halves, which
# FIRSTSHOT_GPU_TESTS=1/2 and 2/2 choose (every other binary in name order; k/n for n parts).
set -euo pipefail
cd "$(dirname "$0")/../.."
MITSUBA=3.9.1 DRJIT=1.5.0 PY=3.12

# The plugins the converted scenes load (read off /proc/self/maps after rendering every
# scene in scenes/), plus the neighbours a converted scene can name.
PLUGINS="area box diffuse hdrfilm independent merge path perspective ply obj point spot srgb
  uniform regular constant directional direct rectangle sphere twosided gaussian tent
  stratified bitmap envmap roughconductor conductor plastic roughplastic blendbsdf serialized"

echo "== .gl: Vulkan loader and GL dispatch (amd64 .deb)"
mkdir -p .gl /tmp/firstshot-apt-amd64/partial
o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/firstshot-apt-amd64)
apt-get "${o[@]}" update -qq
(cd .gl && apt-get "${o[@]}" download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2 2>&1 | grep -v unsandboxed || true)

echo "== .whl: Mitsuba $MITSUBA and Dr.Jit $DRJIT for Python $PY, trimmed"
rm -rf .whl && mkdir -p .whl/download .whl/site
python3 -m pip download -q --no-deps --only-binary=:all: --python-version $PY --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
  -d .whl/download "mitsuba==$MITSUBA" "drjit==$DRJIT"
for w in .whl/download/*.whl; do python3 -m zipfile -e "$w" .whl/site; done
m=.whl/site/mitsuba
rm -rf "$m/include" "$m/data/srgb.coeff" "$m"/llvm_ad_* "$m"/cuda_ad_mono* "$m"/cuda_ad_spectral* "$m"/scalar_spectral* \
  "$m"/scalar_mono* .whl/site/drjit/include
mkdir -p "$m/plugins.keep"
for p in $PLUGINS; do [ -f "$m/plugins/$p.so" ] && mv "$m/plugins/$p.so" "$m/plugins.keep/"; done
rm -rf "$m/plugins" && mv "$m/plugins.keep" "$m/plugins"
(cd .whl/site && tar czf ../site.tar.gz .) && rm -rf .whl/site .whl/download

echo "== .gpu: release builds, stripped"
cargo build --release --locked -q
harness=$(cargo bench --locked --bench harness --no-run --message-format=json 2>/dev/null |
  python3 -c "import sys, json
for l in sys.stdin:
    m = json.loads(l)
    if m.get('reason') == 'compiler-artifact' and m['target']['name'] == 'harness' and m.get('executable'): print(m['executable'])")
rm -rf .gpu && mkdir -p .gpu
strip -o .gpu/firstshot target/release/firstshot
strip -o .gpu/harness "$harness"
gzip -9 .gpu/firstshot .gpu/harness
# The builds find the repository (refs/, tools/, scenes/) by the path they were built in:
# run.sh makes that path lead to the repository there.
realpath . >.gpu/manifest_dir
# The Sierpinski scene's reference (refs/ holds only the Cornell boxes'): a long Mitsuba render
# at 256 x 256, e.g. the peers study's own (`peers_reference_sierpinski_*.exr` in its --out).
# Without one, the study on the GPU renders its own with cuda_ad_rgb.
if [ -n "${FIRSTSHOT_SIERPINSKI_REFERENCE:-}" ]; then
    cp "$FIRSTSHOT_SIERPINSKI_REFERENCE" .gpu/sierpinski.full.exr
fi
if [ -n "${FIRSTSHOT_GPU_TESTS:-}" ]; then
    echo "== .gpu/tests: the GPU tests' binaries"
    # Not those that need what a bare GPU machine lacks: Mitsuba (.whl is not carried with
    # them), Slurm, the Kubernetes schema, an X display, Debian's glTF models; nor the
    # naga-only and host-only ones.
    skip=" mitsuba slurm kubernetes viewer gltf harness_pure wgsl_validate kernel_bindings scene_load docs "
    want=" ${FIRSTSHOT_GPU_TESTS} "
    mkdir -p .gpu/tests && rm -f .gpu/tests/*.gz
    # The library's unit-test binary and the command line's share the crate's name: the
    # library's is named firstshot_lib. "k/n" keeps every n-th binary of the rest, from the k-th.
    cargo test --release --locked --no-run --lib --tests --message-format=json 2>/dev/null |
        python3 -c "import sys, json
for l in sys.stdin:
    m = json.loads(l)
    if m.get('reason') == 'compiler-artifact' and m.get('executable') and m['profile']['test']:
        kind = '_lib' if 'lib' in m['target']['kind'] else ''
        print(m['target']['name'] + kind, m['executable'])" | sort |
        while read -r name exe; do
            case "$skip" in *" $name "*) continue ;; esac
            echo "$name $exe"
        done | {
            i=0
            while read -r name exe; do
                i=$((i + 1))
                case "$FIRSTSHOT_GPU_TESTS" in
                1) ;;
                */*) k=${FIRSTSHOT_GPU_TESTS%/*} n=${FIRSTSHOT_GPU_TESTS#*/}
                    [ $(((i - 1) % n + 1)) = "$k" ] || continue ;;
                *) case "$want" in *" $name "*) ;; *) continue ;; esac ;;
                esac
                strip -o ".gpu/tests/$name" "$exe" && gzip -9f ".gpu/tests/$name"
            done
        }
    ls .gpu/tests
    [ "$(du -sm .gpu | cut -f1)" -lt 48 ] ||
        echo "warning: .gpu is $(du -sh .gpu | cut -f1): with the tracked files, more than a device call carries; pack fewer tests"
fi
du -sh .gl .whl .gpu
echo "tracked files: $(git ls-files -z | xargs -0 du -cb | tail -1 | cut -f1) bytes"
