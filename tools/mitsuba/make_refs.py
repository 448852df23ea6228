"""Makes reference images for firstshot scenes with Mitsuba 3 (through convert.py).

    .venv/bin/python tools/mitsuba/make_refs.py scenes/my_scene.toml [more scenes]
        [--spp 256] [--passes 8] [--direct-spp 256] [--direct-passes 4]
        [--out refs] [--width W --height H] [--firstshot target/release/firstshot]

For each scene it writes ``OUT/<stem>.full.exr`` (full global illumination) and
``OUT/<stem>.direct.exr`` (emission + one reflection, what ``--iterations 0`` computes),
each the mean of ``passes`` independent renders of ``spp`` samples, and
``OUT/<stem>.json`` with how they were made: Mitsuba's version and variant, samples, time,
and their noise. The noise is measured, not guessed: the means of the even and of the odd
passes are independent, and half of their image error (``firstshot compare``, the figure
of docs/ALGORITHM.md section 3) is the error of the whole mean. It prints a row for the
table in refs/README.md.

Noise falls as 1 / sqrt(samples): to halve it, render four times as many.
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
import render  # noqa: E402


def compare(firstshot, a, b):
    """(relative RMSE, ratio of means) of A against B from `firstshot compare`."""
    out = subprocess.run([firstshot, "compare", a, b], check=True, capture_output=True, text=True).stdout
    rmse = float(re.search(r"relative RMSE\s+([0-9.eE+-]+|NaN)", out).group(1))
    return rmse, out


def make(scene, which, spp, passes, args, log):
    stem = os.path.splitext(os.path.basename(scene))[0]
    out = os.path.join(args.out, f"{stem}.{which}.exr")
    log(f"{stem} {which}: {passes} passes of {spp} samples")
    image, stats, halves = render.render(
        scene, spp, args.width, args.height, which == "direct", args.variant, args.seed, passes, log
    )
    render.write_exr(out, image)
    record = dict(stats)
    if halves is not None:
        with tempfile.TemporaryDirectory() as tmp:
            even, odd = os.path.join(tmp, "even.exr"), os.path.join(tmp, "odd.exr")
            render.write_exr(even, halves[0])
            render.write_exr(odd, halves[1])
            rmse, _ = compare(args.firstshot, even, odd)
            record["noise_image_error"] = 0.5 * rmse
    record["file"] = os.path.relpath(out, ROOT)
    return record


def main(argv=None):
    ap = argparse.ArgumentParser(description="Reference images for firstshot scenes, by Mitsuba 3.")
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--out", default=os.path.join(ROOT, "refs"))
    ap.add_argument("--spp", type=int, default=256, help="samples per pass, full images")
    ap.add_argument("--passes", type=int, default=8, help="passes, full images (>= 2 for a noise figure)")
    ap.add_argument("--direct-spp", type=int, default=256)
    ap.add_argument("--direct-passes", type=int, default=4)
    ap.add_argument("--width", type=int)
    ap.add_argument("--height", type=int)
    ap.add_argument("--variant", default="auto")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--firstshot", default=os.path.join(ROOT, "target", "release", "firstshot"))
    args = ap.parse_args(argv)
    if not os.path.exists(args.firstshot):
        sys.exit(f"{args.firstshot} not found: build it first (cargo build --release) or pass --firstshot")
    os.makedirs(args.out, exist_ok=True)

    def log(message):
        print(message, file=sys.stderr, flush=True)

    for scene in args.scenes:
        stem = os.path.splitext(os.path.basename(scene))[0]
        records = [
            make(scene, "full", args.spp, args.passes, args, log),
            make(scene, "direct", args.direct_spp, args.direct_passes, args, log),
        ]
        with open(os.path.join(args.out, f"{stem}.json"), "w") as f:
            json.dump(records, f, indent=2)
        for r in records:
            minutes = (r["load_seconds"] + r["render_seconds"]) / 60.0
            noise = r.get("noise_image_error")
            print(
                f"| `{os.path.basename(r['file'])}` | `{os.path.relpath(scene, ROOT)}` | {r['spp']} | "
                f"{minutes:.1f} min | {'?' if noise is None else f'{noise:.4f}'} |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
