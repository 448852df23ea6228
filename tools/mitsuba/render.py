"""Renders a firstshot scene with Mitsuba 3 (through convert.py) and writes a float EXR.

    python tools/mitsuba/render.py scenes/cornell_box.toml --spp 256 --out out/cb_mitsuba.exr
        [--width W --height H] [--direct] [--variant auto|llvm_ad_rgb|cuda_ad_rgb]
        [--seed S] [--passes K] [--stats out/cb_mitsuba.json] [--quiet]

``--direct`` renders emission plus one reflection (``max_depth = 2``), what firstshot's
``--iterations 0`` computes; without it, full global illumination (no depth limit, Russian
roulette from depth 5). ``--passes K`` renders K independent images of ``--spp`` samples
each (seeds S .. S + K - 1) and writes their mean, so that long references fit in memory and
carry a noise estimate: ``--halves`` also writes the means of the even and of the odd passes
(OUT.even.exr, OUT.odd.exr). The two are independent, so their difference has four times
the variance of the whole mean: half of ``firstshot compare OUT.even.exr OUT.odd.exr`` is
the whole mean's own error, in the sense of docs/ALGORITHM.md section 3
(``make_refs.py`` does exactly that).

The llvm variant needs an LLVM shared library; where ``DRJIT_LIBLLVM_PATH`` is not set this
script looks for Debian's ``libllvm19`` (``tools/mitsuba/setup.sh`` installs it).
"""

import argparse
import glob
import json
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

def find_libllvm():
    """An LLVM shared library Dr.Jit's llvm back end works with (LLVM 15 crashes it)."""
    for pattern in (
        "/usr/lib/x86_64-linux-gnu/libLLVM.so.19*",
        "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
        "/usr/lib/llvm-19/lib/libLLVM*.so*",
        "/usr/lib/aarch64-linux-gnu/libLLVM.so.19*",
        "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
    ):
        found = sorted(glob.glob(pattern))
        if found:
            return found[0]
    return None


def prepare_environment():
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        lib = find_libllvm()
        if lib:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib


def pick_variant(mi, wanted):
    if wanted != "auto":
        return wanted
    if "cuda_ad_rgb" in mi.variants():
        try:
            mi.set_variant("cuda_ad_rgb")
            return "cuda_ad_rgb"
        except Exception:  # no CUDA device or driver: the CPU variant
            pass
    return "llvm_ad_rgb"


def render(scene_path, spp, width=None, height=None, direct=False, variant="auto", seed=0, passes=1, log=None):
    """(image as a float32 numpy array H x W x 3, stats dict)."""
    prepare_environment()
    start = time.perf_counter()
    import mitsuba as mi
    import numpy as np

    variant = pick_variant(mi, variant)
    mi.set_variant(variant)
    import convert
    import maxphong

    maxphong.register()
    with tempfile.TemporaryDirectory(prefix="firstshot-mitsuba-") as mesh_dir:
        probe = convert.load(scene_path)["camera"]
        w, h = int(width or probe["width"]), int(height or probe["height"])
        # Mitsuba splits a large sample count into passes that fit in memory by itself.
        d = convert.mitsuba_dict(scene_path, mesh_dir, w, h, spp=spp, max_depth=2 if direct else -1)
        scene = mi.load_dict(d)
    loaded = time.perf_counter()
    images = []
    for k in range(passes):
        images.append(np.array(mi.render(scene, spp=spp, seed=seed + k), dtype=np.float32)[:, :, :3])
        if log:
            log(f"  pass {k + 1}/{passes}: {time.perf_counter() - start:.1f} s")
    mean = np.mean(images, axis=0).astype(np.float32)
    stats = {
        "renderer": "mitsuba",
        "mitsuba_version": mi.__version__,
        "variant": variant,
        "scene": scene_path,
        "image": [w, h],
        "spp": spp * passes,
        "passes": passes,
        "direct": direct,
        "seed": seed,
        "load_seconds": loaded - start,
        "render_seconds": time.perf_counter() - loaded,
    }
    halves = None
    if passes >= 2:
        halves = (
            np.mean(images[0::2], axis=0).astype(np.float32),
            np.mean(images[1::2], axis=0).astype(np.float32),
        )
    return mean, stats, halves


def write_exr(path, image):
    import mitsuba as mi

    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    mi.Bitmap(image, mi.Bitmap.PixelFormat.RGB).write(path)


def main(argv=None):
    ap = argparse.ArgumentParser(description="Render a firstshot scene with Mitsuba 3.")
    ap.add_argument("scene")
    ap.add_argument("--out", required=True, help="EXR to write (linear float RGB)")
    ap.add_argument("--spp", type=int, default=64, help="samples per pixel (per pass)")
    ap.add_argument("--width", type=int)
    ap.add_argument("--height", type=int)
    ap.add_argument("--direct", action="store_true", help="emission + one reflection (max_depth 2)")
    ap.add_argument("--variant", default="auto", help="auto (cuda_ad_rgb if it works, else llvm_ad_rgb) or a name")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--passes", type=int, default=1)
    ap.add_argument("--halves", action="store_true", help="also write OUT.even.exr and OUT.odd.exr (--passes >= 2)")
    ap.add_argument("--stats", help="JSON with the version, variant, samples, times, noise")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    log = None if args.quiet else (lambda m: print(m, file=sys.stderr))
    try:
        image, stats, halves = render(
            args.scene, args.spp, args.width, args.height, args.direct, args.variant, args.seed, args.passes, log
        )
    except ImportError as e:
        print(f"error: {e}: set up the Python environment with tools/mitsuba/setup.sh", file=sys.stderr)
        return 3
    write_exr(args.out, image)
    if args.halves and halves is not None:
        stem = args.out[:-4] if args.out.endswith(".exr") else args.out
        write_exr(stem + ".even.exr", halves[0])
        write_exr(stem + ".odd.exr", halves[1])
    stats["total_seconds"] = time.perf_counter() - t0
    if args.stats:
        with open(args.stats, "w") as f:
            json.dump(stats, f, indent=2)
    if not args.quiet:
        print(json.dumps(stats), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
