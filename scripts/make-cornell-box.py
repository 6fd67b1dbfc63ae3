#!/usr/bin/env python3
"""Writes scenes/cornell-box.gltf (+ .bin and the floor texture PNG).

drender's bundled scene: a Cornell box in the same frame as the classic one
(box [-1,1]^3, camera at z = 3.9), with every material feature drender has:
coloured Lambertian-ish walls, a ceiling area light (radiometric emission via
KHR_materials_emissive_strength), a rough metallic sphere, a checker-textured
floor, and a tall dielectric box under a TRS node. Python stdlib only; the
outputs are committed, so building drender does not need Python.
"""
import base64, json, math, os, struct, zlib

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes")


def png_rgb(path, w, h, pixel):
    raw = b"".join(b"\x00" + bytes(c for x in range(w) for c in pixel(x, y)) for y in range(h))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    with open(path, "wb") as f:
        f.write(data)


class Builder:
    def __init__(self):
        self.bin = bytearray()
        self.views, self.accessors, self.meshes = [], [], []

    def _accessor(self, data, fmt, comp, typ, count, target, minmax=None):
        while len(self.bin) % 4:
            self.bin.append(0)
        off = len(self.bin)
        self.bin += struct.pack("<" + fmt * len(data), *data)
        self.views.append({"buffer": 0, "byteOffset": off, "byteLength": len(self.bin) - off, "target": target})
        acc = {"bufferView": len(self.views) - 1, "componentType": comp, "count": count, "type": typ}
        if minmax:
            acc["min"], acc["max"] = minmax
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def mesh(self, name, pos, nrm, uv, idx, material):
        n = len(pos) // 3
        mins = [min(pos[i::3]) for i in range(3)]
        maxs = [max(pos[i::3]) for i in range(3)]
        attrs = {"POSITION": self._accessor(pos, "f", 5126, "VEC3", n, 34962, (mins, maxs)),
                 "NORMAL": self._accessor(nrm, "f", 5126, "VEC3", n, 34962)}
        if uv:
            attrs["TEXCOORD_0"] = self._accessor(uv, "f", 5126, "VEC2", n, 34962)
        ind = self._accessor(idx, "I", 5125, "SCALAR", len(idx), 34963)
        self.meshes.append({"name": name, "primitives": [{"attributes": attrs, "indices": ind, "material": material}]})
        return len(self.meshes) - 1


def quad(corners, normal, uv_scale=1.0):
    """corners counter-clockwise seen from the side `normal` points to."""
    pos = [c for p in corners for c in p]
    nrm = list(normal) * 4
    uv = [0, uv_scale, uv_scale, uv_scale, uv_scale, 0, 0, 0]
    return pos, nrm, uv, [0, 1, 2, 0, 2, 3]


def box(sx, sy, sz):
    pos, nrm, idx = [], [], []
    faces = [((1, 0, 0), (0, 1, 0), (0, 0, 1)), ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
             ((0, 1, 0), (0, 0, 1), (1, 0, 0)), ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
             ((0, 0, 1), (1, 0, 0), (0, 1, 0)), ((0, 0, -1), (0, 1, 0), (1, 0, 0))]
    for n, a, b in faces:
        base = len(pos) // 3
        for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            p = [n[i] + s * a[i] + t * b[i] for i in range(3)]
            pos += [p[0] * sx, p[1] * sy, p[2] * sz]
            nrm += list(n)
        idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return pos, nrm, None, idx


def sphere(r, nu=48, nv=24):
    pos, nrm, uv, idx = [], [], [], []
    for j in range(nv + 1):
        th = math.pi * j / nv
        for i in range(nu + 1):
            ph = 2 * math.pi * i / nu
            n = (math.sin(th) * math.sin(ph), math.cos(th), math.sin(th) * math.cos(ph))
            pos += [r * c for c in n]
            nrm += list(n)
            uv += [i / nu, j / nv]
    for j in range(nv):
        for i in range(nu):
            a, b = j * (nu + 1) + i, (j + 1) * (nu + 1) + i
            if j != 0:
                idx += [a, b, a + 1]
            if j != nv - 1:
                idx += [a + 1, b, b + 1]
    return pos, nrm, uv, idx


def main():
    B = Builder()
    materials = [
        {"name": "white", "pbrMetallicRoughness": {"baseColorFactor": [0.73, 0.71, 0.68, 1], "metallicFactor": 0.0, "roughnessFactor": 0.9}},
        {"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [0.63, 0.065, 0.05, 1], "metallicFactor": 0.0, "roughnessFactor": 0.9}},
        {"name": "green", "pbrMetallicRoughness": {"baseColorFactor": [0.14, 0.45, 0.091, 1], "metallicFactor": 0.0, "roughnessFactor": 0.9}},
        {"name": "light", "pbrMetallicRoughness": {"baseColorFactor": [0.78, 0.78, 0.78, 1], "metallicFactor": 0.0, "roughnessFactor": 1.0},
         "emissiveFactor": [1.0, 0.76, 0.37], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 17.0}}},
        {"name": "rough-gold", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.78, 0.34, 1], "metallicFactor": 1.0, "roughnessFactor": 0.35}},
        {"name": "checker-floor", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 0.8}},
    ]
    meshes = [
        B.mesh("floor", *quad([(-1, -1, 1), (1, -1, 1), (1, -1, -1), (-1, -1, -1)], (0, 1, 0), 4.0), 5),
        B.mesh("ceiling", *quad([(-1, 1, -1), (1, 1, -1), (1, 1, 1), (-1, 1, 1)], (0, -1, 0)), 0),
        B.mesh("back", *quad([(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1)], (0, 0, 1)), 0),
        B.mesh("red-wall", *quad([(-1, -1, 1), (-1, -1, -1), (-1, 1, -1), (-1, 1, 1)], (1, 0, 0)), 1),
        B.mesh("green-wall", *quad([(1, -1, -1), (1, -1, 1), (1, 1, 1), (1, 1, -1)], (-1, 0, 0)), 2),
        B.mesh("light", *quad([(-0.25, 0.99, -0.2), (0.25, 0.99, -0.2), (0.25, 0.99, 0.2), (-0.25, 0.99, 0.2)], (0, -1, 0)), 3),
        B.mesh("tall-box", *box(0.28, 0.6, 0.28), 0),
        B.mesh("gold-sphere", *sphere(0.35), 4),
    ]
    s = math.sin(math.radians(-17) / 2)
    c = math.cos(math.radians(-17) / 2)
    nodes = [{"name": m["name"], "mesh": i} for i, m in enumerate(B.meshes[:6])]
    nodes.append({"name": "tall-box", "mesh": meshes[6], "translation": [-0.36, -0.4, -0.3], "rotation": [0, s, 0, c]})
    nodes.append({"name": "gold-sphere", "mesh": meshes[7], "translation": [0.4, -0.65, 0.3]})
    nodes.append({"name": "camera", "camera": 0, "translation": [0, 0, 3.9]})
    png_rgb(os.path.join(OUT, "cornell-box-checker.png"), 64, 64,
            lambda x, y: (225, 220, 205) if ((x // 8) + (y // 8)) % 2 == 0 else (60, 70, 110))
    doc = {
        "asset": {"version": "2.0", "generator": "drender scripts/make-cornell-box.py"},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0, "scenes": [{"name": "cornell-box", "nodes": list(range(len(nodes)))}],
        "nodes": nodes, "meshes": B.meshes, "materials": materials,
        "cameras": [{"name": "front", "type": "perspective",
                     "perspective": {"yfov": math.radians(39.3077), "aspectRatio": 1.0, "znear": 0.01}}],
        "textures": [{"source": 0, "sampler": 0}],
        "images": [{"uri": "cornell-box-checker.png"}],
        "samplers": [{"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}],
        "buffers": [{"uri": "cornell-box.bin", "byteLength": len(B.bin)}],
        "bufferViews": B.views, "accessors": B.accessors,
    }
    with open(os.path.join(OUT, "cornell-box.bin"), "wb") as f:
        f.write(B.bin)
    with open(os.path.join(OUT, "cornell-box.gltf"), "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
