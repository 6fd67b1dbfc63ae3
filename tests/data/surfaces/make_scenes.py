#!/usr/bin/env python3
"""Writes the small glTF scenes of tests/cli_gltf_surfaces.sh (stdlib only).

The outputs are checked in, so the tests never need to run this; rerun it
after changing it:  python3 tests/data/surfaces/make_scenes.py
  normal_mapped.gltf  a glossy floor with a normal map (no TANGENT: generated),
                      a wall, a point light and a dim environment
  alpha.gltf          a floor under a MASK cut-out (checker alpha) and a BLEND
                      pane (alpha 0.5), lit through both by a point light
"""
import base64
import json
import math
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))


def png(width, height, channels, pixel):
    """8-bit PNG, RGB (channels 3) or RGBA (4); pixel(x, y) -> tuple of 0..255."""
    raw = b"".join(b"\x00" + bytes(c for x in range(width) for c in pixel(x, y)) for y in range(height))

    def chunk(tag, body):
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xffffffff)

    ctype = 2 if channels == 3 else 6
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, ctype, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def uri(data, mime):
    return "data:%s;base64,%s" % (mime, base64.b64encode(data).decode())


class Doc:
    def __init__(self):
        self.bin = bytearray()
        self.d = {"asset": {"version": "2.0", "generator": "drender tests/data/surfaces/make_scenes.py"},
                  "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "accessors": [],
                  "bufferViews": [], "materials": [], "textures": [], "images": [], "samplers": []}

    def accessor(self, fmt, comps, values, typ, ctype, target, minmax=False):
        while len(self.bin) % 4:
            self.bin.append(0)
        off = len(self.bin)
        self.bin += struct.pack("<%d%s" % (len(values), fmt), *values)
        self.d["bufferViews"].append({"buffer": 0, "byteOffset": off, "byteLength": len(self.bin) - off,
                                      "target": target})
        a = {"bufferView": len(self.d["bufferViews"]) - 1, "componentType": ctype,
             "count": len(values) // comps, "type": typ}
        if minmax:
            a["min"] = [min(values[i::comps]) for i in range(comps)]
            a["max"] = [max(values[i::comps]) for i in range(comps)]
        self.d["accessors"].append(a)
        return len(self.d["accessors"]) - 1

    def quad(self, name, p, e1, e2, material):
        """Parallelogram p, p+e1, p+e1+e2, p+e2 facing cross(e1, e2); u along e1, v along -e2."""
        pts = [p, [p[i] + e1[i] for i in range(3)], [p[i] + e1[i] + e2[i] for i in range(3)],
               [p[i] + e2[i] for i in range(3)]]
        n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]]
        ln = math.sqrt(sum(c * c for c in n))
        n = [c / ln for c in n]
        pos = self.accessor("f", 3, [c for q in pts for c in q], "VEC3", 5126, 34962, True)
        nor = self.accessor("f", 3, n * 4, "VEC3", 5126, 34962)
        uv = self.accessor("f", 2, [0, 1, 1, 1, 1, 0, 0, 0], "VEC2", 5126, 34962)
        idx = self.accessor("H", 1, [0, 1, 2, 0, 2, 3], "SCALAR", 5123, 34963)
        self.d["meshes"].append({"name": name, "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nor,
                                                                              "TEXCOORD_0": uv},
                                                               "indices": idx, "material": material}]})
        self.node({"name": name, "mesh": len(self.d["meshes"]) - 1})

    def node(self, n):
        self.d["nodes"].append(n)
        self.d["scenes"][0]["nodes"].append(len(self.d["nodes"]) - 1)

    def texture(self, data):
        if not self.d["samplers"]:
            self.d["samplers"].append({"wrapS": 10497, "wrapT": 10497})
        self.d["images"].append({"uri": uri(data, "image/png")})
        self.d["textures"].append({"source": len(self.d["images"]) - 1, "sampler": 0})
        return len(self.d["textures"]) - 1

    def camera_and_light(self, eye, target, light_pos, intensity):
        # look-at as a quaternion: camera looks along its -Z
        f = [target[i] - eye[i] for i in range(3)]
        lf = math.sqrt(sum(c * c for c in f))
        f = [c / lf for c in f]
        r = [f[1] * 0 - f[2] * 1, f[2] * 0 - f[0] * 0, f[0] * 1 - f[1] * 0]   # f x up(0,1,0)
        lr = math.sqrt(sum(c * c for c in r))
        r = [c / lr for c in r]
        u = [r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]]
        z = [-c for c in f]
        m = [[r[0], u[0], z[0]], [r[1], u[1], z[1]], [r[2], u[2], z[2]]]
        w = math.sqrt(max(0.0, 1 + m[0][0] + m[1][1] + m[2][2])) / 2
        q = [(m[2][1] - m[1][2]) / (4 * w), (m[0][2] - m[2][0]) / (4 * w), (m[1][0] - m[0][1]) / (4 * w), w]
        self.d["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.01}}]
        self.node({"name": "camera", "camera": 0, "translation": eye, "rotation": q})
        self.d["extensionsUsed"] = ["KHR_lights_punctual"]
        self.d["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": intensity}]}}
        self.node({"name": "light", "translation": light_pos, "extensions": {"KHR_lights_punctual": {"light": 0}}})

    def write(self, name):
        self.d["buffers"] = [{"byteLength": len(self.bin), "uri": uri(bytes(self.bin), "application/octet-stream")}]
        for k in ("textures", "images", "samplers"):
            if not self.d[k]:
                del self.d[k]
        with open(os.path.join(HERE, name), "w") as f:
            json.dump(self.d, f, indent=1)
            f.write("\n")


def bump(x, y):
    """A normal map of tilted bumps: every texel a different unit normal, z > 0."""
    a, b = 0.6 * math.sin(1.7 * x + 0.4 * y), 0.6 * math.cos(1.3 * y - 0.9 * x)
    l = math.sqrt(a * a + b * b + 1)
    return tuple(int(round((c / l * 0.5 + 0.5) * 255)) for c in (a, b, 1.0))


def normal_mapped():
    doc = Doc()
    nt = doc.texture(png(8, 8, 3, bump))
    doc.d["materials"] = [
        {"name": "bumpy", "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.5, 0.3, 1], "metallicFactor": 0.0,
                                                   "roughnessFactor": 0.35},
         "normalTexture": {"index": nt, "scale": 1.0}},
        {"name": "wall", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.6, 1], "metallicFactor": 0.0,
                                                  "roughnessFactor": 1.0}}]
    doc.quad("floor", [-1, 0, 1], [2, 0, 0], [0, 0, -2], 0)
    doc.quad("wall", [-1, 0, -1], [2, 0, 0], [0, 2, 0], 1)
    doc.camera_and_light([0.3, 1.6, 2.4], [0, 0.2, 0], [0.6, 1.5, 0.8], 6.0)
    doc.d["extensionsUsed"].append("DR_environment")
    doc.d["extensions"]["DR_environment"] = {"color": [0.3, 0.3, 0.35], "strength": 1.0}
    doc.write("normal_mapped.gltf")


def alpha():
    doc = Doc()
    leaf = doc.texture(png(8, 8, 4, lambda x, y: (255, 255, 255, 255 if (x // 2 + y // 2) % 2 else 0)))
    doc.d["materials"] = [
        {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.6, 0.5, 1], "metallicFactor": 0.0,
                                                   "roughnessFactor": 0.6}},
        {"name": "leaf", "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.7, 0.2, 1], "metallicFactor": 0.0,
                                                  "roughnessFactor": 1.0, "baseColorTexture": {"index": leaf}},
         "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True},
        {"name": "pane", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.3, 0.3, 0.5], "metallicFactor": 0.0,
                                                  "roughnessFactor": 1.0},
         "alphaMode": "BLEND", "doubleSided": True}]
    doc.quad("floor", [-1.5, 0, 1.5], [3, 0, 0], [0, 0, -3], 0)
    doc.quad("leaf", [-1.0, 0.5, -0.8], [1.4, 0, 0], [0, 0, 1.4], 1)
    doc.quad("pane", [-0.2, 0.8, -0.6], [1.2, 0, 0], [0, 0, 1.2], 2)
    doc.camera_and_light([0.2, 2.6, 2.2], [0, 0.2, 0], [0.1, 2.2, 0.1], 8.0)
    doc.write("alpha.gltf")


if __name__ == "__main__":
    normal_mapped()
    alpha()
