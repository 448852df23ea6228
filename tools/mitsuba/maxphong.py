"""The max-Phong BRDF of docs/SCENE_FORMAT.md as a Mitsuba 3 BSDF plugin, ``maxphong``.

    f(w_in, w_out) = kd / pi + ks * max(0, cos psi)^n / max(cos theta_in, cos theta_out)

psi is the angle between w_out and the mirror direction of w_in; the thetas are the angles
to the normal. One-sided: 0 when either direction is below the surface, as firstshot's
``src/scene/brdf.rs`` has it (its ``max(0, cos psi)^0`` is 1 everywhere, and so is ours).

Sampling is a mixture of a cosine-weighted hemisphere and the lobe ``(n + 1) / (2 pi)
cos^n alpha`` about the mirror direction, the lobe chosen with a probability in proportion
to its share of the albedo at normal incidence, but never above 0.9, so that the cosine
part, whose density is positive wherever f is, is always drawn from. ``pdf`` is the mixture
density in solid angle, and ``sample``'s weight is exactly ``eval / pdf``.

Dict keys: ``diffuse`` (kd, RGB), ``specular`` (ks, RGB), ``shininess`` (n >= 0).
``register()`` makes the plugin known to ``mi.load_dict`` under the name ``maxphong``.
"""

import math

import drjit as dr
import mitsuba as mi


def _rgb(props, key):
    if key in props.keys():
        v = props[key]
        return [float(v[0]), float(v[1]), float(v[2])]
    return [0.0, 0.0, 0.0]


def _mean(c):
    return (c[0] + c[1] + c[2]) / 3.0


class MaxPhong(mi.BSDF):
    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        kd = _rgb(props, "diffuse")
        ks = _rgb(props, "specular")
        self.n = float(props.get("shininess", 0.0))
        self.kd_values, self.ks_values = kd, ks
        self.kd = mi.Color3f(kd)
        self.ks = mi.Color3f(ks)
        # Share of the lobe at normal incidence: kd against ks * 2 pi / (n + 2).
        d = _mean(kd)
        s = _mean(ks) * 2.0 * math.pi / (self.n + 2.0)
        self.p_lobe = 0.0 if s <= 0.0 else min(0.9, s / (d + s))
        reflection = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        self.m_components = [reflection]
        self.m_flags = reflection

    # ---- the formula -------------------------------------------------------------------

    def _lobe_power(self, c):
        """max(0, c)^n, with x^0 = 1 everywhere (as firstshot's powf)."""
        if self.n == 0.0:
            return dr.full(mi.Float, 1.0, dr.width(c))
        return dr.power(dr.maximum(c, 0.0), self.n)

    def _cos_psi(self, wi, wo):
        # (2 cos_i n - w_i) . w_o in the local frame, symmetric in (wi, wo) as the Rust code.
        return 2.0 * wi.z * wo.z - dr.dot(wi, wo)

    def _f(self, wi, wo):
        """f(wi, wo) in 1/sr, 0 below the surface."""
        lobe = self._lobe_power(self._cos_psi(wi, wo)) / dr.maximum(wi.z, wo.z)
        f = self.kd * dr.inv_pi + self.ks * lobe
        valid = (wi.z > 0.0) & (wo.z > 0.0)
        return dr.select(valid, f, 0.0)

    def _pdf(self, wi, wo):
        cos_pdf = dr.maximum(wo.z, 0.0) * dr.inv_pi
        lobe_pdf = (self.n + 1.0) * dr.inv_two_pi * self._lobe_power(self._cos_psi(wi, wo))
        if self.n == 0.0:
            lobe_pdf = dr.select(self._cos_psi(wi, wo) > 0.0, lobe_pdf, 0.0)
        p = (1.0 - self.p_lobe) * cos_pdf + self.p_lobe * lobe_pdf
        return dr.select((wi.z > 0.0) & (wo.z > 0.0), p, 0.0)

    # ---- the mi.BSDF interface ---------------------------------------------------------

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.wi
        use_lobe = sample1 < self.p_lobe
        wo_cos = mi.warp.square_to_cosine_hemisphere(sample2)
        # The lobe about the mirror direction: cos alpha = u^(1 / (n + 1)).
        cos_a = dr.power(sample2.x, 1.0 / (self.n + 1.0))
        sin_a = dr.safe_sqrt(1.0 - cos_a * cos_a)
        phi = dr.two_pi * sample2.y
        local = mi.Vector3f(sin_a * dr.cos(phi), sin_a * dr.sin(phi), cos_a)
        mirror = mi.Vector3f(-wi.x, -wi.y, wi.z)
        wo_lobe = mi.Frame3f(mirror).to_world(local)
        wo = dr.select(use_lobe, wo_lobe, wo_cos)

        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = wo
        bs.pdf = self._pdf(wi, wo)
        bs.eta = 1.0
        bs.sampled_type = dr.select(
            use_lobe, mi.UInt32(+mi.BSDFFlags.GlossyReflection), mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        )
        bs.sampled_component = mi.UInt32(0)
        ok = active & (wi.z > 0.0) & (wo.z > 0.0) & (bs.pdf > 0.0)
        weight = self._f(wi, wo) * wo.z / dr.select(ok, bs.pdf, 1.0)
        bs.pdf = dr.select(ok, bs.pdf, 0.0)
        return bs, dr.select(ok, weight, 0.0)

    def eval(self, ctx, si, wo, active=True):
        return dr.select(active, self._f(si.wi, wo) * dr.maximum(wo.z, 0.0), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        return dr.select(active, self._pdf(si.wi, wo), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def traverse(self, callback):
        pass

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        return f"MaxPhong[diffuse={self.kd_values}, specular={self.ks_values}, shininess={self.n}]"


_registered = False


def register():
    """Registers ``maxphong`` with Mitsuba (after ``mi.set_variant``); idempotent."""
    global _registered
    if not _registered:
        mi.register_bsdf("maxphong", lambda props: MaxPhong(props))
        _registered = True
