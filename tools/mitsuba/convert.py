"""firstshot scene (TOML, docs/SCENE_FORMAT.md) -> Mitsuba 3 scene.

The shape rules are written again here, triangle for triangle in the order firstshot's
loader (src/scene/shapes.rs, src/scene/load.rs) produces them, so that
``tests/mitsuba.rs`` can compare the two geometries exactly. The conventions of the
conversion:

- every shape becomes one triangle mesh (a PLY file) with flat face normals; a quad is the
  triangles (v0, v1, v2), (v0, v2, v3), a polygon of an OBJ file the fan (v0, vi, vi+1); a
  glTF file (a `gltf` shape) is read by ``gltf_reader.py``, written apart from the loader,
  its materials mapped to max-Phong by the documented rule;
- surfaces are one-sided: Mitsuba's ``diffuse`` and our ``maxphong`` are black seen from
  behind, as firstshot's patches are; ``two_sided = true`` wraps the BSDF in ``twosided``;
- an area light is a one-sided ``area`` emitter of its radiance on a surface that reflects
  nothing; ``emission`` on a shape is the same emitter on that shape's own material;
- a point light is a ``point`` emitter of intensity power / (4 pi);
- ``[environment] radiance`` is a ``constant`` emitter;
- the camera is ``perspective`` with ``fov_axis = "y"``, aimed by ``look_at``: Mitsuba's
  image right is forward x up and pixel (0, 0) the top-left corner, as ours.

As a program it prints a summary, or the geometry as JSON (``--geometry``, for the tests):

    python tools/mitsuba/convert.py scenes/cornell_box.toml [--geometry]
"""

import argparse
import json
import math
import os
import struct
import sys
import tomllib

SIERPINSKI_MAX_LEVEL = 8


class ConvertError(Exception):
    pass


# ---- small vector helpers (plain floats: the geometry is compared in f64) -------------


def add(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def mul(a, s):
    return [a[0] * s, a[1] * s, a[2] * s]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def norm(a):
    return math.sqrt(dot(a, a))


def triangle_area(t):
    return 0.5 * norm(cross(sub(t[1], t[0]), sub(t[2], t[0])))


# ---- shapes ----------------------------------------------------------------------------


class Transform:
    """scale, then rotate (right-handed, about an axis through the origin), then translate."""

    def __init__(self, table=None):
        table = table or {}
        s = table.get("scale", 1.0)
        self.scale = [float(x) for x in s] if isinstance(s, list) else [float(s)] * 3
        r = table.get("rotate", [0.0, 1.0, 0.0, 0.0])
        axis = [float(x) for x in r[:3]]
        length = norm(axis)
        if length == 0.0:
            raise ConvertError("transform.rotate: the axis must not be zero")
        self.axis = mul(axis, 1.0 / length)
        self.angle = math.radians(float(r[3]))
        self.translate = [float(x) for x in table.get("translate", [0.0, 0.0, 0.0])]

    def apply(self, p):
        p = [p[0] * self.scale[0], p[1] * self.scale[1], p[2] * self.scale[2]]
        # Rodrigues: p cos a + (k x p) sin a + k (k . p)(1 - cos a).
        k, c, s = self.axis, math.cos(self.angle), math.sin(self.angle)
        p = add(add(mul(p, c), mul(cross(k, p), s)), mul(k, dot(k, p) * (1.0 - c)))
        return add(p, self.translate)


def fan(polygon):
    return [[polygon[0], polygon[i], polygon[i + 1]] for i in range(1, len(polygon) - 1)]


def box_triangles(lo, hi):
    """12 outward triangles, in the order of shapes::box_triangles."""
    out = []
    for a in range(3):

        def corner(at_max, u, v):
            p = [0.0, 0.0, 0.0]
            p[a] = hi[a] if at_max else lo[a]
            b, c = (a + 1) % 3, (a + 2) % 3
            p[b] = hi[b] if u > 0.5 else lo[b]
            p[c] = hi[c] if v > 0.5 else lo[c]
            return p

        ccw = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
        top = [corner(True, u, v) for u, v in ccw]
        bottom = [corner(False, u, v) for u, v in ccw][::-1]
        out += fan(top) + fan(bottom)
    return out


def sierpinski(center, size, level):
    """4^level tetrahedra, 4 outward triangles each, in the order of shapes::sierpinski."""
    h = size * math.sqrt(2.0 / 3.0)
    r = size / math.sqrt(3.0)

    def base(k):
        t = 2.0 * math.pi * k / 3.0
        return add(center, [r * math.sin(t), -h / 4.0, -r * math.cos(t)])

    apex = add(center, [0.0, 0.75 * h, 0.0])
    tetrahedra = [[apex, base(0.0), base(1.0), base(2.0)]]
    for _ in range(min(level, SIERPINSKI_MAX_LEVEL)):
        tetrahedra = [[mul(add(t[c], q), 0.5) for q in t] for t in tetrahedra for c in range(4)]
    out = []
    for a, b0, b1, b2 in tetrahedra:
        out += [[a, b1, b0], [a, b0, b2], [a, b2, b1], [b0, b1, b2]]
    return out


def parse_obj(path):
    """(positions, faces): faces as (list of 0-based indices, usemtl name or None)."""
    positions, faces, current = [], [], None
    with open(path, encoding="utf-8", errors="replace") as f:
        for number, raw in enumerate(f, 1):
            tokens = raw.split("#", 1)[0].split()
            if not tokens:
                continue
            if tokens[0] == "v":
                positions.append([float(x) for x in tokens[1:4]])
            elif tokens[0] == "f":
                indices = []
                for token in tokens[1:]:
                    i = int(token.split("/")[0])
                    indices.append(i - 1 if i > 0 else len(positions) + i)
                if len(indices) < 3:
                    raise ConvertError(f"{path} line {number}: a face needs at least 3 vertices")
                faces.append((indices, current))
            elif tokens[0] == "usemtl":
                current = raw.split("#", 1)[0].strip()[len("usemtl") :].strip()
    return positions, faces


def load(path):
    """The scene as plain data: camera, environment, materials, surfaces (with their
    triangles and per-triangle materials, in scene space) and lights."""
    with open(path, "rb") as f:
        doc = tomllib.load(f)
    base_dir = os.path.dirname(os.path.abspath(path))
    materials = doc.get("materials", {})
    surfaces = []
    for i, s in enumerate(doc.get("shapes", [])):
        kind = s["type"]
        material = s.get("material")
        transform = Transform(s.get("transform"))
        if kind in ("quad", "triangle"):
            tris = fan([[float(x) for x in v] for v in s["vertices"]])
            mats = [material] * len(tris)
        elif kind == "box":
            tris = [[transform.apply(p) for p in t] for t in box_triangles(s["min"], s["max"])]
            mats = [material] * len(tris)
        elif kind == "sierpinski":
            center = [float(x) for x in s["center"]]
            tris = [[transform.apply(p) for p in t] for t in sierpinski(center, float(s["size"]), int(s["level"]))]
            mats = [material] * len(tris)
        elif kind == "mesh":
            positions, faces = parse_obj(os.path.join(base_dir, s["file"]))
            positions = [transform.apply(p) for p in positions]
            tris, mats = [], []
            for indices, usemtl in faces:
                face = fan([positions[k] for k in indices])
                tris += face
                mats += [usemtl or material] * len(face)
        elif kind == "gltf":
            import gltf_reader

            written = s["file"]
            origin = f'shapes[{i}] (gltf "{written}")'
            o = transform.apply([0.0, 0.0, 0.0])
            axes = [sub(transform.apply(e), o) for e in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])]
            placement = [[axes[0][r], axes[1][r], axes[2][r], o[r]] for r in range(3)] + [[0.0, 0.0, 0.0, 1.0]]
            parts, found = gltf_reader.read(os.path.join(base_dir, written), placement, material, origin)
            materials = {**materials, **found}
            for part in parts:
                if "emission" in s:
                    part["emission"] = [float(x) for x in s["emission"]]
                part["two_sided"] = part["two_sided"] or bool(s.get("two_sided", False))
                for m in part["materials"]:
                    if m not in materials:
                        raise ConvertError(f"shapes[{i}]: unknown material {m!r}")
            surfaces += parts
            continue
        else:
            raise ConvertError(f"shapes[{i}]: unknown shape type {kind!r}")
        for m in mats:
            if m not in materials:
                raise ConvertError(f"shapes[{i}]: unknown material {m!r}")
        surfaces.append(
            {
                "origin": f"shapes[{i}] ({kind})",
                "triangles": tris,
                "materials": mats,
                "emission": [float(x) for x in s.get("emission", [0.0, 0.0, 0.0])],
                "two_sided": bool(s.get("two_sided", False)),
            }
        )
    return {
        "camera": doc["camera"],
        "environment": [float(x) for x in doc.get("environment", {}).get("radiance", [0.0, 0.0, 0.0])],
        "materials": materials,
        "surfaces": surfaces,
        "lights": doc.get("lights", []),
    }


# ---- Mitsuba -----------------------------------------------------------------------------


def write_ply(path, triangles):
    """Binary PLY, three unshared vertices per triangle (flat normals by construction)."""
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {3 * len(triangles)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(triangles)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(b"".join(struct.pack("<3f", *p) for t in triangles for p in t))
        f.write(b"".join(struct.pack("<B3i", 3, 3 * k, 3 * k + 1, 3 * k + 2) for k in range(len(triangles))))


def rgb(values):
    return {"type": "rgb", "value": [float(x) for x in values]}


def bsdf(material, two_sided):
    if material is None:  # an area light's surface: reflects nothing
        b = {"type": "diffuse", "reflectance": rgb([0.0, 0.0, 0.0])}
    elif material["type"] == "diffuse":
        b = {"type": "diffuse", "reflectance": rgb(material["albedo"])}
    elif material["type"] == "phong":
        b = {
            "type": "maxphong",
            "diffuse": [float(x) for x in material["diffuse"]],
            "specular": [float(x) for x in material["specular"]],
            "shininess": float(material["shininess"]),
        }
    else:
        raise ConvertError(f"unknown material type {material['type']!r}")
    return {"type": "twosided", "material": b} if two_sided else b


# Texels a side of the falloff texture that carries a spot light's cone (`spot`).
SPOT_TEXELS = 1024

# Mitsuba's spot maps its texture over the tangent plane up to tan(cutoff_angle); beyond
# about 80 degrees the cone's middle would shrink to a few texels.
SPOT_MAX_OUTER_ANGLE = 80.0

# The fewest texels from the inner to the outer angle: the texture is filtered bilinearly,
# which departs from the falloff by up to a texel's change of it.
SPOT_MIN_RAMP_TEXELS = 8


def spot_falloff(cd, inner_angle, outer_angle):
    """glTF's (KHR_lights_punctual) cone falloff at the cosine cd to the axis, as
    docs/SCENE_FORMAT.md writes it (angles in degrees)."""
    import numpy as np

    cos_inner, cos_outer = math.cos(math.radians(inner_angle)), math.cos(math.radians(outer_angle))
    scale = 1.0 / max(0.001, cos_inner - cos_outer)
    return np.clip(cd * scale - cos_outer * scale, 0.0, 1.0) ** 2


def spot(light, i):
    """A spot light as Mitsuba's `spot` whose texture is glTF's falloff. Mitsuba's own falloff
    is linear in the angle between `beam_width` and `cutoff_angle`, glTF's quadratic in the
    cosine: here Mitsuba's cone is full up to the outer angle (its linear ramp squeezed into
    a thousandth of a degree, where glTF's falloff is 0 anyway), and the texture, which
    Mitsuba looks up at uv = (1 + x / (z tan(cutoff))) / 2, (1 + y / (z tan(cutoff))) / 2 for
    the light-space direction (x, y, z), holds glTF's falloff at each texel's direction
    (`tools/mitsuba/check_spot.py` checks both against the formula)."""
    import mitsuba as mi
    import numpy as np

    inner, outer = float(light.get("inner_angle", 0.0)), float(light.get("outer_angle", 45.0))
    if outer > SPOT_MAX_OUTER_ANGLE:
        raise ConvertError(
            f"lights[{i}]: a spot's outer_angle above {SPOT_MAX_OUTER_ANGLE:g} degrees is not converted to Mitsuba"
        )
    tan_inner, tan_outer = math.tan(math.radians(inner)), math.tan(math.radians(outer))
    ramp = (tan_outer - tan_inner) / (2.0 * tan_outer) * SPOT_TEXELS
    if ramp < SPOT_MIN_RAMP_TEXELS:
        raise ConvertError(
            f"lights[{i}]: a spot whose falloff (inner_angle {inner:g} to outer_angle {outer:g}) spans fewer "
            f"than {SPOT_MIN_RAMP_TEXELS} of its texture's {SPOT_TEXELS} texels is not converted to Mitsuba"
        )
    position = [float(x) for x in light["position"]]
    axis = [float(x) for x in light["direction"]]
    length = norm(axis)
    axis = [x / length for x in axis]
    up = [0.0, 1.0, 0.0] if abs(axis[1]) < 0.9 else [1.0, 0.0, 0.0]
    c = ((np.arange(SPOT_TEXELS) + 0.5) / SPOT_TEXELS * 2.0 - 1.0) * tan_outer
    x, y = c[None, :], c[:, None]
    falloff = spot_falloff(1.0 / np.sqrt(1.0 + x * x + y * y), inner, outer)
    texture = np.repeat(falloff.astype(np.float32)[:, :, None], 3, axis=2)
    return {
        "type": "spot",
        "intensity": rgb(light["intensity"]),
        "cutoff_angle": outer,
        "beam_width": outer - 1e-3,
        "to_world": mi.ScalarTransform4f().look_at(
            origin=position, target=[p + a for p, a in zip(position, axis)], up=up
        ),
        "texture": {"type": "bitmap", "bitmap": mi.Bitmap(texture), "raw": True},
    }


def mitsuba_dict(path, mesh_dir, width=None, height=None, spp=64, max_depth=-1, rr_depth=5, seed=0):
    """A dict for ``mi.load_dict``; PLY meshes are written into ``mesh_dir``. Call
    ``maxphong.register()`` (after ``mi.set_variant``) before loading it."""
    import mitsuba as mi

    scene = load(path)
    cam = scene["camera"]
    w, h = int(width or cam["width"]), int(height or cam["height"])
    os.makedirs(mesh_dir, exist_ok=True)
    integrator = {"type": "path", "max_depth": int(max_depth), "rr_depth": int(rr_depth)}
    out = {
        "type": "scene",
        "integrator": integrator,
        "sensor": {
            "type": "perspective",
            "fov": float(cam["fov_y"]),
            "fov_axis": "y",
            "near_clip": 1e-3 * norm(sub(cam["look_at"], cam["position"])),
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[float(x) for x in cam["position"]],
                target=[float(x) for x in cam["look_at"]],
                up=[float(x) for x in cam["up"]],
            ),
            "sampler": {"type": "independent", "sample_count": int(spp), "seed": int(seed)},
            "film": {
                "type": "hdrfilm",
                "width": w,
                "height": h,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
                "component_format": "float32",
            },
        },
    }
    if any(c > 0.0 for c in scene["environment"]):
        out["environment"] = {"type": "constant", "radiance": rgb(scene["environment"])}

    def add_mesh(key, triangles, material, two_sided, emission):
        ply = os.path.join(mesh_dir, f"{key}.ply")
        write_ply(ply, triangles)
        shape = {"type": "ply", "filename": ply, "face_normals": True, "bsdf": bsdf(material, two_sided)}
        if emission is not None and any(c > 0.0 for c in emission):
            if two_sided:
                raise ConvertError(f"{key}: a two-sided emitter has no one-to-one Mitsuba equivalent")
            shape["emitter"] = {"type": "area", "radiance": rgb(emission)}
        out[key] = shape

    for i, s in enumerate(scene["surfaces"]):
        # One mesh per (shape, material): OBJ files may switch material per face.
        groups = {}
        for t, m in zip(s["triangles"], s["materials"]):
            groups.setdefault(m, []).append(t)
        for j, (m, tris) in enumerate(groups.items()):
            add_mesh(f"shape{i}_{j}", tris, scene["materials"][m], s["two_sided"], s["emission"])
    for i, light in enumerate(scene["lights"]):
        if light["type"] == "point":
            intensity = [float(p) / (4.0 * math.pi) for p in light["power"]]
            out[f"light{i}"] = {
                "type": "point",
                "position": [float(x) for x in light["position"]],
                "intensity": rgb(intensity),
            }
        elif light["type"] == "area":
            quad = [[float(x) for x in v] for v in light["vertices"]]
            add_mesh(f"light{i}", fan(quad), None, False, light["radiance"])
        elif light["type"] == "directional":
            # Mitsuba's `irradiance` is, as ours, W/m^2 on a surface facing the light.
            out[f"light{i}"] = {
                "type": "directional",
                "direction": [float(x) for x in light["direction"]],
                "irradiance": rgb(light["irradiance"]),
            }
        elif light["type"] == "spot":
            out[f"light{i}"] = spot(light, i)
        else:
            raise ConvertError(f"lights[{i}]: unknown light type {light['type']!r}")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--geometry", action="store_true", help="print every surface's triangles as JSON")
    args = ap.parse_args(argv)
    try:
        scene = load(args.scene)
    except (ConvertError, KeyError, OSError, tomllib.TOMLDecodeError) as e:
        print(f"error: {args.scene}: {e}", file=sys.stderr)
        return 2
    if args.geometry:
        json.dump({"surfaces": scene["surfaces"], "materials": scene["materials"]}, sys.stdout)
        print()
        return 0
    for s in scene["surfaces"]:
        area = sum(triangle_area(t) for t in s["triangles"])
        print(f"{s['origin']}: {len(s['triangles'])} triangles, area {area:.6g}")
    print(f"{len(scene['lights'])} lights")
    return 0


if __name__ == "__main__":
    sys.exit(main())
