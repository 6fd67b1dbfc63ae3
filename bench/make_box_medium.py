#!/usr/bin/env python3
"""Writes bench media part vi's scenes: the peer's Cornell box
(../shared/bench/peer-cornell-box.gltf) with a medium in part of it, as
smoke or fog usually sits in a real scene: a closed cube of side 0.5 m
floating in the front left, clear of the two boxes (a twentieth of the
picture, a tenth of the room seen from the floor), bounding either the
smoke cube's density grid (GRID_URI: tests/data/media/smoke.raw, 16^3, copied
beside OUT by the caller) or a homogeneous fog. The box's own surfaces,
lights and camera are unchanged.

    make_box_medium.py PEER.gltf OUT.gltf grid GRID_URI
    make_box_medium.py PEER.gltf OUT.gltf fog

Standard library only (the cube's buffer goes inline as a data URI)."""
import base64
import json
import struct
import sys

SIDE = 0.5
CENTRE = (-0.45, -0.45, 0.5)


def cube_buffer():
    """The cube's 8 corners (float32) and 12 outward triangles (uint16)."""
    h = SIDE / 2
    pos = []
    for z in (-h, h):
        for y in (-h, h):
            for x in (-h, h):
                pos += [CENTRE[0] + x, CENTRE[1] + y, CENTRE[2] + z]
    # corner index: x + 2 y + 4 z; each face's two triangles wound outwards
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    idx = []
    for a, b, c, d in quads:
        idx += [a, b, c, a, c, d]
    data = struct.pack("<%df" % len(pos), *pos) + struct.pack("<%dH" % len(idx), *idx)
    lo = [min(pos[i::3]) for i in range(3)]
    hi = [max(pos[i::3]) for i in range(3)]
    return data, len(pos) * 4, len(idx) * 2, lo, hi


def main():
    if len(sys.argv) < 4 or sys.argv[3] not in ("grid", "fog") or (sys.argv[3] == "grid" and len(sys.argv) < 5):
        sys.exit(__doc__)
    with open(sys.argv[1]) as f:
        doc = json.load(f)
    data, pos_bytes, idx_bytes, lo, hi = cube_buffer()
    b = len(doc["buffers"])
    doc["buffers"].append({"byteLength": len(data),
                           "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()})
    v = len(doc["bufferViews"])
    doc["bufferViews"] += [{"buffer": b, "byteOffset": 0, "byteLength": pos_bytes},
                           {"buffer": b, "byteOffset": pos_bytes, "byteLength": idx_bytes}]
    a = len(doc["accessors"])
    doc["accessors"] += [{"bufferView": v, "componentType": 5126, "count": 8, "type": "VEC3", "min": lo, "max": hi},
                         {"bufferView": v + 1, "componentType": 5123, "count": 36, "type": "SCALAR"}]
    medium = {"extinction": [6, 6, 6], "albedo": [0.85, 0.8, 0.75], "g": 0.2}
    if sys.argv[3] == "grid":
        medium["extinction"] = [4, 4, 4]
        medium["density"] = {"uri": sys.argv[4], "resolution": [16, 16, 16]}
    m = len(doc["materials"])
    doc["materials"].append({"name": "medium", "extensions": {"DR_medium": medium}})
    doc["meshes"].append({"name": "medium", "primitives": [{"attributes": {"POSITION": a}, "indices": a + 1,
                                                            "material": m}]})
    doc["nodes"].append({"name": "medium", "mesh": len(doc["meshes"]) - 1})
    doc["scenes"][doc.get("scene", 0)]["nodes"].append(len(doc["nodes"]) - 1)
    doc["extensionsUsed"] = sorted(set(doc.get("extensionsUsed", [])) | {"DR_medium"})
    with open(sys.argv[2], "w") as f:
        json.dump(doc, f)


if __name__ == "__main__":
    main()
