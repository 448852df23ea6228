#!/usr/bin/env python3
"""Writes the Cornell box with its ceiling, back wall and side walls as OBJ meshes of
N x N squares (two triangles each, in row order): the geometry of scenes/cornell_box.toml,
so its reference (refs/cornell_box.full.exr) holds. A scene of many small diffuse patches,
as imported architecture has (docs/PERFORMANCE.md, "Diffuse patches need no line a step").

    python3 tools/scenes/mesh_walls.py OUT_DIR [N]      # N = 48 by default
    firstshot OUT_DIR/cornell_box_mesh_walls.toml --width 256 --height 256
"""
import json
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.join(HERE, "..", "..", "scenes", "cornell_box.toml")
WALLS = ("ceiling", "back wall", "right wall", "left wall")


def grid_obj(path, quad, n):
    """The quad v0..v3 as n x n squares, vertex (i, j) the bilinear blend at (i/n, j/n);
    written under a temporary name, then renamed."""
    with open(path + ".tmp", "w") as f:
        for j in range(n + 1):
            for i in range(n + 1):
                u, w = i / n, j / n
                p = [(1 - w) * ((1 - u) * quad[0][k] + u * quad[1][k]) + w * ((1 - u) * quad[3][k] + u * quad[2][k])
                     for k in range(3)]
                f.write("v %r %r %r\n" % tuple(p))
        for j in range(n):
            for i in range(n):
                a = j * (n + 1) + i + 1
                # Counter-clockwise as the quad: (v0, v1, v2) and (v0, v2, v3) of each square.
                f.write("f %d %d %d\nf %d %d %d\n" % (a, a + 1, a + n + 2, a, a + n + 2, a + n + 1))
    os.replace(path + ".tmp", path)


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    out, n = sys.argv[1], sys.argv[2] if len(sys.argv) == 3 else "48"
    if not n.isdigit() or int(n) < 1:
        sys.exit(f"mesh_walls.py: N must be a whole number of at least 1, got {n!r}")
    n = int(n)
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        sys.exit(f"mesh_walls.py: cannot make the folder {out!r}: {e.strerror}")
    blocks = open(SOURCE).read().split("[[shapes]]")
    kept = [blocks[0]]
    for block in blocks[1:]:
        wall = next((w for w in WALLS if ("# " + w) in block.split("\n", 1)[0]), None)
        if wall:
            name = wall.replace(" ", "_") + ".obj"
            quad = json.loads(re.search(r"vertices = (\[\[.*\]\])", block).group(1))
            grid_obj(os.path.join(out, name), quad, n)
            block = block.replace('type = "quad"', 'type = "mesh"\nfile = "%s"' % name)
            block = re.sub(r"vertices = .*\n", "", block)
        kept.append(block)
    scene = os.path.join(out, "cornell_box_mesh_walls.toml")
    tmp = scene + ".tmp"
    with open(tmp, "w") as f:
        f.write("[[shapes]]".join(kept))
    os.replace(tmp, scene)
    print(scene)


if __name__ == "__main__":
    main()
