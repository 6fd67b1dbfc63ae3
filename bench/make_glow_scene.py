#!/usr/bin/env python3
"""Writes bench part n's scene: a grey floor lit only by a panel of
2 x N x N triangles (N = 32 unless given: 2048 small ones; N = 1: two
large ones) whose emissive texture (IMAGE, written by the caller with
oiiotool) is black but for three small spots, the way real assets paint
their glowing parts. The camera sits between floor and panel.

    make_glow_scene.py OUT.gltf IMAGE_URI [N]

Standard library only (the buffer goes inline as a data URI)."""
import base64
import json
import struct
import sys


def grid(pos, uv, idx, y, half, n, down):
    """An n x n grid of quads in the plane y (facing down when down)."""
    base = len(pos) // 3
    for j in range(n + 1):
        for i in range(n + 1):
            pos += [-half + 2 * half * i / n, y, -half + 2 * half * j / n]
            uv += [i / n, j / n]
    for j in range(n):
        for i in range(n):
            a = base + j * (n + 1) + i
            b, c = a + 1, a + n + 1
            d = c + 1
            idx += [a, b, c, b, d, c] if down else [a, c, b, b, c, d]


def main():
    out, image = sys.argv[1], sys.argv[2]
    n = int(sys.argv[3]) if len(sys.argv) > 3 else 32
    pos, uv, idx = [], [], []
    grid(pos, uv, idx, 0.0, 2.0, 1, False)
    floor_indices = len(idx)
    grid(pos, uv, idx, 2.0, 1.5, n, True)
    blobs = [struct.pack("<%df" % len(pos), *pos), struct.pack("<%df" % len(uv), *uv),
             struct.pack("<%dI" % len(idx), *idx)]
    data = b"".join(blobs)
    views, offset = [], 0
    for b in blobs:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(b)})
        offset += len(b)
    n_vertices = len(pos) // 3
    gltf = {
        "asset": {"version": "2.0", "generator": "drender bench/make_glow_scene.py"},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2]}],
        "nodes": [{"mesh": 0}, {"mesh": 1},
                  {"camera": 0, "translation": [0, 1.2, 3.2], "rotation": [-0.2164, 0, 0, 0.9763]}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01, "aspectRatio": 1}}],
        "buffers": [{"byteLength": len(data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
        "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n_vertices, "type": "VEC3",
             "min": [min(pos[k::3]) for k in range(3)], "max": [max(pos[k::3]) for k in range(3)]},
            {"bufferView": 1, "componentType": 5126, "count": n_vertices, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5125, "count": floor_indices, "type": "SCALAR"},
            {"bufferView": 2, "byteOffset": 4 * floor_indices, "componentType": 5125,
             "count": len(idx) - floor_indices, "type": "SCALAR"},
        ],
        "materials": [
            {"name": "floor",
             "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.7, 0.7, 1], "metallicFactor": 0,
                                      "roughnessFactor": 1}},
            {"name": "glow", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0},
             "emissiveFactor": [1, 1, 1], "emissiveTexture": {"index": 0},
             "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 300}}},
        ],
        "textures": [{"source": 0}],
        "images": [{"uri": image}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]},
            {"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 3, "material": 1}]},
        ],
    }
    with open(out, "w") as f:
        json.dump(gltf, f)


if __name__ == "__main__":
    main()
