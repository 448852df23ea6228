"""Measurements of the maxphong plugin that tests/mitsuba.rs holds against firstshot's own
BRDF code (src/scene/brdf.rs). Prints one JSON object:

    python tools/mitsuba/check_maxphong.py pairs|albedo MATERIALS.json

MATERIALS.json is a list of {"diffuse": [r, g, b], "specular": [r, g, b], "shininess": n}.
For each material:

- ``pairs``: seeded random direction pairs (local frame, normal = +z, some below the
  surface) with the plugin's f(wi, wo) and f(wo, wi) (eval / cos theta_o), its pdf, and
  ``sample``'s consistency with ``pdf`` and ``eval``;
- ``albedo``: at several incident angles, the directional albedo estimated from the
  plugin's own sampling (the mean of ``sample``'s weights, with its standard error) and
  from uniform hemisphere sampling of ``eval``, and the integral of ``pdf`` over the
  hemisphere (<= 1; 1 minus the lobe's mass below the horizon).
"""

import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import render  # noqa: E402  (sets DRJIT_LIBLLVM_PATH before Mitsuba loads)

render.prepare_environment()
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
import numpy as np  # noqa: E402

mi.set_variant("llvm_ad_rgb")
import maxphong  # noqa: E402

maxphong.register()

SAMPLES = 1 << 20
PAIRS = 256
COS_IN = [1.0, 0.8, 0.5, 0.2, 0.05]


def interaction(wi):
    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = mi.Vector3f(wi[:, 0], wi[:, 1], wi[:, 2])
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.sh_frame = mi.Frame3f(si.n)
    return si


def vec(a):
    return mi.Vector3f(a[:, 0], a[:, 1], a[:, 2])


def np3(c):
    return np.array(c, dtype=np.float64).T if dr.width(c) > 1 else np.array(c, dtype=np.float64).reshape(1, 3)


def random_directions(rng, n, upper_fraction=0.85):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    below = rng.random(n) > upper_fraction
    v[below, 2] *= -1.0
    return v


def check(material, seed, mode):
    bsdf = mi.load_dict({"type": "maxphong", **material})
    ctx = mi.BSDFContext()
    rng = np.random.default_rng(seed)
    wi = random_directions(rng, PAIRS)
    wo = random_directions(rng, PAIRS)
    si_a = interaction(wi)
    si_b = interaction(wo)
    cos_o = np.maximum(wo[:, 2], 1e-30)
    cos_i = np.maximum(wi[:, 2], 1e-30)
    f_ab = np3(bsdf.eval(ctx, si_a, vec(wo))) / cos_o[:, None]
    f_ba = np3(bsdf.eval(ctx, si_b, vec(wi))) / cos_i[:, None]
    pdf = np.array(bsdf.pdf(ctx, si_a, vec(wo)), dtype=np.float64)
    e2, p2 = bsdf.eval_pdf(ctx, si_a, vec(wo))
    pairs = {
        "wi": wi.tolist(),
        "wo": wo.tolist(),
        "f": f_ab.tolist(),
        "f_swapped": f_ba.tolist(),
        "pdf": pdf.tolist(),
        "eval_pdf_agrees": bool(
            np.allclose(np3(e2) / cos_o[:, None], f_ab) and np.allclose(np.array(p2, dtype=np.float64), pdf)
        ),
    }
    if mode == "pairs":
        return {"material": material, "pairs": pairs}

    albedo = []
    for mu in COS_IN:
        s = math.sqrt(max(0.0, 1.0 - mu * mu))
        wi_n = np.tile([s, 0.0, mu], (SAMPLES, 1))
        si = interaction(wi_n)
        u1 = mi.Float(rng.random(SAMPLES))
        u2 = mi.Point2f(rng.random(SAMPLES), rng.random(SAMPLES))
        bs, weight = bsdf.sample(ctx, si, u1, u2)
        w = np3(weight)
        # sample() must report the pdf that pdf() gives for the same direction, and a weight
        # equal to eval / pdf.
        pdf_again = np.array(bsdf.pdf(ctx, si, bs.wo), dtype=np.float64)
        bs_pdf = np.array(bs.pdf, dtype=np.float64)
        ok = bs_pdf > 0
        ev = np3(bsdf.eval(ctx, si, bs.wo))
        weight_err = np.max(np.abs(w[ok] - ev[ok] / bs_pdf[ok, None]) / np.maximum(np.abs(w[ok]), 1e-6))
        pdf_err = np.max(np.abs(bs_pdf[ok] - pdf_again[ok]) / pdf_again[ok])
        # Uniform hemisphere sampling: albedo = 2 pi E[f cos], integral of pdf = 2 pi E[pdf].
        uni = np.array(mi.warp.square_to_uniform_hemisphere(mi.Point2f(rng.random(SAMPLES), rng.random(SAMPLES))))
        uni = uni.T
        ev_u = np3(bsdf.eval(ctx, si, vec(uni))) * 2.0 * math.pi
        pdf_u = np.array(bsdf.pdf(ctx, si, vec(uni)), dtype=np.float64) * 2.0 * math.pi
        albedo.append(
            {
                "cos_in": mu,
                "sampled": w.mean(axis=0).tolist(),
                "sampled_stderr": (w.std(axis=0) / math.sqrt(SAMPLES)).tolist(),
                "uniform": ev_u.mean(axis=0).tolist(),
                "uniform_stderr": (ev_u.std(axis=0) / math.sqrt(SAMPLES)).tolist(),
                "pdf_integral": float(pdf_u.mean()),
                "pdf_integral_stderr": float(pdf_u.std() / math.sqrt(SAMPLES)),
                "weight_max_relative_error": float(weight_err),
                "pdf_max_relative_error": float(pdf_err),
                "valid_samples": int(ok.sum()),
            }
        )
    return {"material": material, "albedo": albedo}


def main():
    mode, path = sys.argv[1], sys.argv[2]
    if mode not in ("pairs", "albedo"):
        sys.exit(f"usage: {sys.argv[0]} pairs|albedo MATERIALS.json")
    with open(path) as f:
        materials = json.load(f)
    out = {
        "mitsuba_version": mi.__version__,
        "results": [check(m, seed, mode) for seed, m in enumerate(materials)],
    }
    json.dump(out, sys.stdout)
    print()


if __name__ == "__main__":
    main()
