#!/usr/bin/env python3
"""Writes the small glTF scenes used by tests/cli_optimize*.sh (stdlib only).

The outputs are checked in, so the tests never need Python; rerun this after
changing it:  python3 tests/data/optimize/make_scenes.py

  diffuse.gltf        a diffuse quad ('wall', base colour 0.7 0.4 0.2) filling
                      the view of camera 0, lit by a constant DR_environment;
                      camera 1 sees the same quad from an angle
  texture-true.gltf   the same quad with a 4x4 sRGB base-colour texture
                      (texture-true.png, /images/0), clamp-to-edge
  texture-flat.gltf   ... the same with a flat grey texture (texture-flat.png)
  glossy.gltf         a metal floor ('floor', roughness 0.3) reflecting an
                      emissive area light ('lamp', emissiveStrength 5) that the
                      camera also sees directly, dim constant environment
"""
import json
import math
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))


def png_rgb(width, height, pixel):
    """8-bit RGB PNG; pixel(x, y) -> (r, g, b) in 0..255 (sRGB-encoded)."""
    raw = b"".join(b"\x00" + bytes(c for x in range(width) for c in pixel(x, y))
                   for y in range(height))

    def chunk(tag, body):
        return (struct.pack(">I", len(body)) + tag + body +
                struct.pack(">I", zlib.crc32(tag + body) & 0xffffffff))

    return (b"\x89PNG\r\n\x1a\n" +
            chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def f32(*v):
    return struct.pack("<%df" % len(v), *v)


def quat_axis(axis, angle):
    s = math.sin(angle / 2)
    return [axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2)]


class Doc:
    def __init__(self, name):
        self.name = name
        self.bin = b""
        self.views, self.accessors, self.meshes, self.nodes = [], [], [], []
        self.materials, self.cameras = [], []
        self.extensions_used = set()
        self.extra = {}

    def _acc(self, data, ctype, count, type_, target, minmax=None):
        self.bin += b"\x00" * (-len(self.bin) % 4)
        self.views.append({"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data), "target": target})
        self.bin += data
        a = {"bufferView": len(self.views) - 1, "componentType": ctype, "count": count, "type": type_}
        if minmax:
            a["min"], a["max"] = minmax
        self.accessors.append(a)
        return len(self.accessors) - 1

    def quad(self, corners, normal, material):
        """corners counter-clockwise seen from the side `normal` points to; uv (0,1) at corner 0."""
        pos = [c for p in corners for c in p]
        mins = [min(pos[i::3]) for i in range(3)]
        maxs = [max(pos[i::3]) for i in range(3)]
        attrs = {"POSITION": self._acc(f32(*pos), 5126, 4, "VEC3", 34962, (mins, maxs)),
                 "NORMAL": self._acc(f32(*(list(normal) * 4)), 5126, 4, "VEC3", 34962),
                 "TEXCOORD_0": self._acc(f32(0, 1, 1, 1, 1, 0, 0, 0), 5126, 4, "VEC2", 34962)}
        ind = self._acc(struct.pack("<6H", 0, 1, 2, 0, 2, 3), 5123, 6, "SCALAR", 34963)
        self.meshes.append({"primitives": [{"attributes": attrs, "indices": ind, "material": material}]})
        self.nodes.append({"mesh": len(self.meshes) - 1})

    def camera(self, yfov, translation, rotation):
        self.cameras.append({"type": "perspective",
                             "perspective": {"yfov": yfov, "aspectRatio": 1.0, "znear": 0.05}})
        self.nodes.append({"camera": len(self.cameras) - 1, "translation": translation, "rotation": rotation})

    def write(self):
        doc = {"asset": {"version": "2.0", "generator": "drender tests/data/optimize/make_scenes.py"},
               "scene": 0, "scenes": [{"nodes": list(range(len(self.nodes)))}],
               "nodes": self.nodes, "meshes": self.meshes, "cameras": self.cameras,
               "materials": self.materials,
               "buffers": [{"uri": self.name + ".bin", "byteLength": len(self.bin)}],
               "bufferViews": self.views, "accessors": self.accessors}
        doc.update(self.extra)
        if self.extensions_used:
            doc["extensionsUsed"] = sorted(self.extensions_used)
        with open(os.path.join(HERE, self.name + ".gltf"), "w") as f:
            json.dump(doc, f, indent=1)
            f.write("\n")
        with open(os.path.join(HERE, self.name + ".bin"), "wb") as f:
            f.write(self.bin)


FACING = ([-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0])   # z = 0 plane, normal +z


def front_quad_scene(name, material, extra=None):
    d = Doc(name)
    d.materials.append(material)
    d.quad(FACING, (0, 0, 1), 0)
    # camera 0: straight on from z = 3, the quad fills the view (slightly cropped)
    d.camera(2 * math.atan(0.9 / 3.0), [0, 0, 3], [0, 0, 0, 1])
    # camera 1: from the right, 30 degrees off axis
    a = math.radians(30)
    d.camera(2 * math.atan(0.6 / 3.0), [3 * math.sin(a), 0, 3 * math.cos(a)], quat_axis((0, 1, 0), a))
    d.extra = {"extensions": {"DR_environment": {"color": [1.0, 1.0, 1.0], "strength": 1.0}}}
    d.extensions_used.add("DR_environment")
    if extra:
        d.extra.update(extra)
    return d


def main():
    front_quad_scene("diffuse", {"name": "wall", "pbrMetallicRoughness": {
        "baseColorFactor": [0.7, 0.4, 0.2, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}}).write()

    # 4x4 texture: a colourful pattern, every texel distinct (sRGB bytes)
    def true_texel(x, y):
        return (40 + 60 * x, 230 - 50 * y, 60 + 40 * ((x + 2 * y) % 4))
    with open(os.path.join(HERE, "texture-true.png"), "wb") as f:
        f.write(png_rgb(4, 4, true_texel))
    with open(os.path.join(HERE, "texture-flat.png"), "wb") as f:
        f.write(png_rgb(4, 4, lambda x, y: (128, 128, 128)))
    for which in ("true", "flat"):
        mat = {"name": "canvas", "pbrMetallicRoughness": {
            "baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0,
            "baseColorTexture": {"index": 0}}}
        front_quad_scene("texture-" + which, mat, {
            "textures": [{"source": 0, "sampler": 0}],
            "samplers": [{"magFilter": 9729, "minFilter": 9729, "wrapS": 33071, "wrapT": 33071}],
            "images": [{"uri": "texture-%s.png" % which, "name": "canvas"}]}).write()

    # glossy: metal floor y = 0 (z in [-1.5, 1.5]), lamp: a vertical quad at
    # z = -1.5 facing +z, seen directly (upper half) and mirrored (lower half)
    d = Doc("glossy")
    d.materials.append({"name": "floor", "pbrMetallicRoughness": {
        "baseColorFactor": [0.9, 0.9, 0.9, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.3}})
    d.materials.append({"name": "lamp", "pbrMetallicRoughness": {
        "baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "emissiveFactor": [1.0, 1.0, 1.0],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 5.0}}})
    d.extensions_used.add("KHR_materials_emissive_strength")
    d.quad(([-1.5, 0, 1.5], [1.5, 0, 1.5], [1.5, 0, -1.5], [-1.5, 0, -1.5]), (0, 1, 0), 0)
    d.quad(([-0.6, 0.4, -1.5], [0.6, 0.4, -1.5], [0.6, 1.2, -1.5], [-0.6, 1.2, -1.5]), (0, 0, 1), 1)
    d.camera(0.9, [0, 0.8, 2.2], quat_axis((1, 0, 0), -math.atan2(0.3, 3.7)))
    d.extra = {"extensions": {"DR_environment": {"color": [1.0, 1.0, 1.0], "strength": 0.1}}}
    d.extensions_used.add("DR_environment")
    d.write()


if __name__ == "__main__":
    main()
