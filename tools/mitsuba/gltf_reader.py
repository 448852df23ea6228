"""An independent glTF 2.0 reader for the converter: a `gltf` shape of a firstshot scene
(docs/SCENE_FORMAT.md, "glTF 2.0") as triangles and materials in scene space.

Written from the glTF 2.0 specification and the documented rules of firstshot's loader,
sharing no code with it (`src/scene/gltf.rs` uses the `gltf` crate): ``tests/mitsuba.rs``
compares the two triangle for triangle, and the converted scene renders with Mitsuba 3
against firstshot's image. It reads what the loader reads: `.glb` or `.gltf` (buffers in the
GLB chunk, data URIs or files beside it), the default scene (else the first) and every node
under it (matrix, or translation x rotation x scale, composed down the hierarchy), mode
TRIANGLES with or without indices, metallic-roughness materials mapped to max-Phong, and
`doubleSided`. It does not check the file: the loader's refusals have tests of their own.
"""

import base64
import json
import math
import os
import struct
import urllib.parse

import numpy as np

GLB_MAGIC = 0x46546C67
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
COMPONENT = {5121: ("B", 1), 5123: ("H", 2), 5125: ("I", 4), 5126: ("f", 4)}
TRIANGLES = 4

# docs/SCENE_FORMAT.md: a lobe's shininess is at most this (roughness 0), and a triangle
# is skipped when twice its area is at most 2 x 1e-12 x (its bounding box's diagonal)^2.
MAX_SHININESS = 1.0e4
ZERO_AREA = 1.0e-12


def _document(path):
    """(JSON dict, GLB binary chunk or None)."""
    with open(path, "rb") as f:
        data = f.read()
    if len(data) >= 12 and struct.unpack_from("<I", data, 0)[0] == GLB_MAGIC:
        offset, doc, blob = 12, None, None
        while offset + 8 <= len(data):
            length, kind = struct.unpack_from("<II", data, offset)
            chunk = data[offset + 8 : offset + 8 + length]
            if kind == CHUNK_JSON:
                doc = json.loads(chunk.decode("utf-8"))
            elif kind == CHUNK_BIN and blob is None:
                blob = chunk
            offset += 8 + length
        return doc, blob
    return json.loads(data.decode("utf-8")), None


def _buffers(path, doc, blob):
    out = []
    for i, b in enumerate(doc.get("buffers", [])):
        uri = b.get("uri")
        if uri is None:
            data = blob
        elif uri.startswith("data:"):
            data = base64.b64decode(uri.split(",", 1)[1])
        else:
            with open(os.path.join(os.path.dirname(os.path.abspath(path)), urllib.parse.unquote(uri)), "rb") as f:
                data = f.read()
        out.append(data[: b["byteLength"]])
    return out


def _accessor(doc, buffers, index):
    """The accessor's elements as a list of tuples (VEC3) or of ints (SCALAR)."""
    a = doc["accessors"][index]
    view = doc["bufferViews"][a["bufferView"]]
    fmt, size = COMPONENT[a["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
    stride = view.get("byteStride") or size * width
    data = buffers[view["buffer"]]
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    items = [struct.unpack_from("<" + fmt * width, data, start + k * stride) for k in range(a["count"])]
    return [v[0] for v in items] if width == 1 else items


def _local(node):
    """The node's local matrix (4 x 4, float64) from its column-major matrix or its TRS."""
    if "matrix" in node:
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
    x, y, z, w = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = rotation @ np.diag(node.get("scale", [1.0, 1.0, 1.0]))
    m[:3, 3] = node.get("translation", [0.0, 0.0, 0.0])
    return m


def max_lobe_albedo(shininess, rings=256, steps=512, angles=65):
    """L(n): the largest directional albedo over incident angles of the max-Phong lobe
    with ks = 1, integral of max(0, cos psi)^n cos(theta_out) / max(cos theta_in,
    cos theta_out) over the outgoing hemisphere, by a midpoint rule in (psi, phi) about the
    mirror direction, psi cut where cos^n psi falls below 1e-12 of its peak."""
    n = float(shininess)
    psi_max = math.pi if n == 0.0 else min(math.pi, math.acos(math.exp(math.log(1e-12) / n)))
    psi = (np.arange(rings) + 0.5) * psi_max / rings
    phi = (np.arange(steps) + 0.5) * 2.0 * math.pi / steps
    P, F = np.meshgrid(psi, phi, indexing="ij")
    weight = np.cos(P) ** n * np.sin(P) * (psi_max / rings) * (2.0 * math.pi / steps)
    weight = np.where(np.cos(P) > 0.0, weight, 0.0)
    best = 0.0
    for k in range(angles):
        mu = k / (angles - 1)
        sin_in = math.sqrt(max(0.0, 1.0 - mu * mu))
        # The mirror direction r = (sin_in, 0, mu); e1 = (mu, 0, -sin_in), e2 = (0, 1, 0).
        cos_out = np.cos(P) * mu - np.sin(P) * np.cos(F) * sin_in
        f = np.where(cos_out > 0.0, cos_out / np.maximum(mu, cos_out), 0.0)
        best = max(best, float((weight * f).sum()))
    return best


def metallic_roughness(base, metallic, roughness):
    """The documented mapping of a metallic-roughness material to firstshot's materials
    (docs/SCENE_FORMAT.md, "Materials" under "glTF 2.0"), as a converter material dict."""
    m, r = min(max(metallic, 0.0), 1.0), min(max(roughness, 0.0), 1.0)
    c = [min(max(x, 0.0), 1.0) for x in base]
    t = 1.0 - r
    specular_albedo = [t * (0.04 * (1.0 - m) + x * m) for x in c]
    diffuse = [(1.0 - m) * c[i] * (1.0 - specular_albedo[i]) + m * r * c[i] for i in range(3)]
    if all(a == 0.0 for a in specular_albedo):
        return {"type": "diffuse", "albedo": diffuse}
    shininess = min(0.5 / r**4 - 0.5, MAX_SHININESS) if r > 0.0 else MAX_SHININESS
    lobe = max_lobe_albedo(shininess)
    return {"type": "phong", "diffuse": diffuse, "specular": [a / lobe for a in specular_albedo], "shininess": shininess}


def _zero_area(v):
    lo, hi = np.min(v, axis=0), np.max(v, axis=0)
    size = float(np.linalg.norm(hi - lo))
    double_area = float(np.linalg.norm(np.cross(v[1] - v[0], v[2] - v[0])))
    return not (double_area > 2.0 * ZERO_AREA * size * size)


def read(path, placement, material_override, origin):
    """(surfaces, materials): one surface per triangle primitive, in the loader's order (the
    scene's nodes depth first, a node's mesh before its children); materials named as the
    loader names them, ``{origin} materials[i] "name"``, in the order first met. `placement`
    is the shape's 4 x 4 transform, applied after the nodes'."""
    doc, blob = _document(path)
    buffers = _buffers(path, doc, blob)
    scenes = doc.get("scenes", [])
    scene = scenes[doc.get("scene", 0)]
    surfaces, materials, names = [], {}, {}

    def material_of(index):
        if material_override is not None:
            return material_override
        if index not in names:
            if index is None:
                key, pbr = "the default material", {}
            else:
                mat = doc["materials"][index]
                key = f"materials[{index}]" + (f" {json.dumps(mat['name'], ensure_ascii=False)}" if "name" in mat else "")
                pbr = mat.get("pbrMetallicRoughness", {})
            base = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])[:3]
            name = f"{origin} {key}"
            materials[name] = metallic_roughness(base, pbr.get("metallicFactor", 1.0), pbr.get("roughnessFactor", 1.0))
            names[index] = name
        return names[index]

    def visit(index, parent):
        node = doc["nodes"][index]
        world = parent @ _local(node)
        if "mesh" in node:
            mirrors = np.linalg.det(world[:3, :3]) < 0.0
            mesh = doc["meshes"][node["mesh"]]
            for k, primitive in enumerate(mesh["primitives"]):
                if primitive.get("mode", TRIANGLES) != TRIANGLES:
                    continue
                local = np.array(_accessor(doc, buffers, primitive["attributes"]["POSITION"]), dtype=np.float64)
                points = local @ world[:3, :3].T + world[:3, 3]
                if "indices" in primitive:
                    indices = _accessor(doc, buffers, primitive["indices"])
                else:
                    indices = list(range(len(points)))
                m = primitive.get("material")
                name = material_of(m)
                mat = doc["materials"][m] if m is not None else {}
                strength = mat.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
                emission = [e * strength for e in mat.get("emissiveFactor", [0.0, 0.0, 0.0])]
                triangles = []
                for j in range(0, len(indices) - len(indices) % 3, 3):
                    v = points[[indices[j], indices[j + 1], indices[j + 2]]]
                    if mirrors:
                        v = v[[0, 2, 1]]
                    if not _zero_area(v):
                        triangles.append([[float(x) for x in p] for p in v])
                surfaces.append(
                    {
                        "origin": f"{origin} nodes[{index}] meshes[{node['mesh']}] primitives[{k}]",
                        "triangles": triangles,
                        "materials": [name] * len(triangles),
                        "emission": emission,
                        "two_sided": bool(mat.get("doubleSided", False)),
                    }
                )
        for child in node.get("children", []):
            visit(child, world)

    for root in scene.get("nodes", []):
        visit(root, np.array(placement, dtype=np.float64))
    return surfaces, materials
