"""Measures the converter's spot lights (convert.spot) in Mitsuba, for tests/mitsuba.rs to
hold against firstshot's own cone (scene::SpotCone). Prints one JSON object:

    python tools/mitsuba/check_spot.py SPOTS.json

SPOTS.json is a list of {"light": {a [[lights]] table of type "spot"}, "directions": [[x, y,
z], ...]}. For each spot and direction (world space, any length) the result holds the
radiant intensity (W/sr, rgb) that Mitsuba's converted emitter sends that way: the weight
of `sample_direction` seen from a point two units along the direction, times the squared
distance.
"""

import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import render  # noqa: E402  (sets DRJIT_LIBLLVM_PATH before Mitsuba loads)

render.prepare_environment()
import mitsuba as mi  # noqa: E402

mi.set_variant("scalar_rgb")
import convert  # noqa: E402

DISTANCE = 2.0


def main(argv):
    with open(argv[1]) as f:
        spots = json.load(f)
    results = []
    for i, spot in enumerate(spots):
        light = spot["light"]
        emitter = mi.load_dict(convert.spot(light, i))
        intensities = []
        for d in spot["directions"]:
            length = math.sqrt(sum(x * x for x in d))
            point = [p + DISTANCE * x / length for p, x in zip(light["position"], d)]
            it = mi.Interaction3f()
            it.p = mi.ScalarPoint3f(*point)
            ds, weight = emitter.sample_direction(it, mi.ScalarPoint2f(0.5, 0.5))
            intensities.append([float(weight[c]) * float(ds.dist) ** 2 for c in range(3)])
        results.append({"intensities": intensities})
    json.dump({"results": results}, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
