#!/usr/bin/env python3
"""Writes the small glTF scenes used by tests/test_gltf.c (stdlib only).

The outputs are checked in, so the tests never need Python; rerun this after
changing it:  python3 tests/data/gltf/make_scenes.py
The expected numbers in test_gltf.c follow from the values below.
"""
import base64
import json
import math
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))


def write(name, data):
    mode = "w" if isinstance(data, str) else "wb"
    with open(os.path.join(HERE, name), mode) as f:
        f.write(data)


def png_rgb(width, height, pixel):
    """8-bit RGB PNG; pixel(x, y) -> (r, g, b) in 0..255."""
    raw = b"".join(b"\x00" + bytes(c for x in range(width) for c in pixel(x, y))
                   for y in range(height))

    def chunk(tag, body):
        return (struct.pack(">I", len(body)) + tag + body +
                struct.pack(">I", zlib.crc32(tag + body) & 0xffffffff))

    return (b"\x89PNG\r\n\x1a\n" +
            chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def hdr_rgbe(width, height, pixel):
    """Radiance .hdr, flat (uncompressed) RGBE scanlines, top row first."""
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (height, width))
    for y in range(height):
        for x in range(width):
            rgb = pixel(x, y)
            v = max(rgb)
            if v < 1e-32:
                out += b"\x00\x00\x00\x00"
                continue
            m, e = math.frexp(v)
            scale = m * 256.0 / v
            out += bytes([int(c * scale) for c in rgb] + [e + 128])
    return bytes(out)


def f32(*v):
    return struct.pack("<%df" % len(v), *v)


def data_uri(data, mime="application/octet-stream"):
    return "data:%s;base64,%s" % (mime, base64.b64encode(data).decode())


def pad4(b, fill=b"\x00"):
    return b + fill * (-len(b) % 4)


class Buffer:
    """Accumulates one binary buffer plus its bufferViews and accessors."""

    def __init__(self):
        self.data = b""
        self.views = []
        self.accessors = []

    def view(self, data, stride=None):
        self.data = pad4(self.data)
        v = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(data)}
        if stride:
            v["byteStride"] = stride
        self.data += data
        self.views.append(v)
        return len(self.views) - 1

    def accessor(self, view, ctype, count, type_, offset=0, normalized=False, minmax=None):
        a = {"bufferView": view, "componentType": ctype, "count": count, "type": type_}
        if offset:
            a["byteOffset"] = offset
        if normalized:
            a["normalized"] = True
        if minmax:
            a["min"], a["max"] = minmax
        self.accessors.append(a)
        return len(self.accessors) - 1


FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125
S45 = math.sqrt(0.5)

# 4x4 colour texture: texel (x, y) = (64x, 64y, 128) / 255, top row first
CHECKER = png_rgb(4, 4, lambda x, y: (64 * x, 64 * y, 128))
# 2x2 metallic-roughness texture (linear data)
MR = png_rgb(2, 2, lambda x, y: (0, 100 + 50 * x, 200 * y))


def basic_scene(kind):
    """kind: 'bin' (external .bin + .png files), 'embedded' (data: URIs), 'glb'."""
    b = Buffer()
    # quad in the z=0 plane, normal +z, indexed uint16
    quad = b.view(f32(-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0))
    quad_n = b.view(f32(*(0, 0, 1) * 4))
    quad_uv = b.view(f32(0, 1, 1, 1, 1, 0, 0, 0))
    quad_ix = b.view(struct.pack("<6H", 0, 1, 2, 0, 2, 3))
    # non-indexed triangle, no normals, no uvs, no material
    tri = b.view(f32(0, 0, 0, 1, 0, 0, 0, 1, 0))
    a_quad = b.accessor(quad, FLOAT, 4, "VEC3", minmax=([-1, -1, 0], [1, 1, 0]))
    a_quad_n = b.accessor(quad_n, FLOAT, 4, "VEC3")
    a_quad_uv = b.accessor(quad_uv, FLOAT, 4, "VEC2")
    a_quad_ix = b.accessor(quad_ix, USHORT, 6, "SCALAR")
    a_tri = b.accessor(tri, FLOAT, 3, "VEC3", minmax=([0, 0, 0], [1, 1, 0]))

    if kind == "glb":
        images = [{"bufferView": b.view(CHECKER), "mimeType": "image/png", "name": "checker"},
                  {"bufferView": b.view(MR), "mimeType": "image/png"}]
    elif kind == "embedded":
        images = [{"uri": data_uri(CHECKER, "image/png"), "name": "checker"},
                  {"uri": data_uri(MR, "image/png")}]
    else:
        images = [{"uri": "checker.png", "name": "checker"}, {"uri": "mr.png"}]

    buffer = {"byteLength": len(b.data)}
    if kind == "bin":
        buffer["uri"] = "basic.bin"
    elif kind == "embedded":
        buffer["uri"] = data_uri(b.data)

    doc = {
        "asset": {"version": "2.0", "generator": "drender make_scenes.py"},
        "extensionsUsed": ["KHR_materials_emissive_strength", "KHR_materials_specular",
                           "KHR_lights_punctual", "KHR_materials_iridescence"],
        "scene": 0,
        "scenes": [{"nodes": [0, 2, 3, 4, 5, 6, 7]}],
        "nodes": [
            {"name": "root", "translation": [1, 2, 3], "rotation": [0, S45, 0, S45],
             "scale": [2, 2, 2], "children": [1]},
            {"name": "quad_node", "mesh": 0,
             "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 1]},
            {"name": "mirror", "mesh": 1, "scale": [-1, 1, 1]},
            {"name": "cam_node", "camera": 0, "translation": [0, 1, 5],
             "rotation": [0, S45, 0, S45], "scale": [3, 3, 3]},
            {"name": "ortho_node", "camera": 1},
            {"name": "point_node", "translation": [1, 2, 3],
             "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "spot_node", "translation": [0, 5, 0], "rotation": [-S45, 0, 0, S45],
             "extensions": {"KHR_lights_punctual": {"light": 1}}},
            {"name": "sun_node", "extensions": {"KHR_lights_punctual": {"light": 2}}},
        ],
        "meshes": [
            {"name": "quad", "primitives": [{"attributes": {"POSITION": a_quad, "NORMAL": a_quad_n,
                                                            "TEXCOORD_0": a_quad_uv},
                                             "indices": a_quad_ix, "material": 0}]},
            {"name": "tri", "primitives": [{"attributes": {"POSITION": a_tri}}]},
        ],
        "cameras": [
            {"name": "main_cam", "type": "perspective",
             "perspective": {"yfov": 0.8, "aspectRatio": 1.5, "znear": 0.1}},
            {"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 10}},
        ],
        "materials": [{
            "name": "textured",
            "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.6, 0.4, 1.0], "metallicFactor": 0.25,
                                     "roughnessFactor": 0.5, "baseColorTexture": {"index": 0},
                                     "metallicRoughnessTexture": {"index": 1}},
            "emissiveFactor": [1.0, 0.5, 0.0],
            "doubleSided": True,
            "extensions": {
                "KHR_materials_emissive_strength": {"emissiveStrength": 5.0},
                "KHR_materials_specular": {"specularFactor": 0.0, "specularColorFactor": [0.5, 0.25, 1.0]},
            },
        }],
        "textures": [{"source": 0, "sampler": 0}, {"source": 1}],
        "samplers": [{"wrapS": 33071, "wrapT": 33648}],
        "images": images,
        "buffers": [buffer],
        "bufferViews": b.views,
        "accessors": b.accessors,
        "extensions": {
            "KHR_lights_punctual": {"lights": [
                {"name": "bulb", "type": "point", "color": [1.0, 0.5, 0.25], "intensity": 10, "range": 5},
                {"type": "spot", "intensity": 20, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
                {"name": "sun", "type": "directional"},
            ]},
            "DR_environment": {"color": [0.1, 0.2, 0.3], "strength": 2},
        },
    }
    return doc, b.data


def write_glb(name, doc, bin_data):
    js = pad4(json.dumps(doc, separators=(",", ":")).encode(), b" ")
    bn = pad4(bin_data)
    body = (struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(bn), b"BIN\x00") + bn)
    write(name, struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)


def layout_scene():
    """Interleaved strip with byteStride and normalized uint16 UVs, uint8 and
    uint32 indices, a fan, non-uniform scale on normals, no "scenes" array."""
    b = Buffer()
    pos = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)]
    uvs = [(0, 0), (65535, 0), (0, 32768), (65535, 65535)]
    inter = b"".join(f32(*p) + struct.pack("<2H", *uv) for p, uv in zip(pos, uvs))
    v_inter = b.view(inter, stride=16)
    v_n = b.view(f32(*(S45, S45, 0) * 4))
    v_ix8 = b.view(bytes([0, 1, 2, 3]))
    v_ix32 = b.view(struct.pack("<4I", 0, 1, 2, 3))
    v_tri = b.view(f32(0, 0, 0, 1, 0, 0, 0, 0, 1) + f32(0, 0, 1, 0, 0, 1))
    a_pos = b.accessor(v_inter, FLOAT, 4, "VEC3")
    a_uv = b.accessor(v_inter, USHORT, 4, "VEC2", offset=12, normalized=True)
    a_n = b.accessor(v_n, FLOAT, 4, "VEC3")
    a_ix8 = b.accessor(v_ix8, UBYTE, 4, "SCALAR")
    a_ix32 = b.accessor(v_ix32, UINT, 4, "SCALAR")
    a_tri = b.accessor(v_tri, FLOAT, 3, "VEC3")
    a_tri_uv1 = b.accessor(v_tri, FLOAT, 3, "VEC2", offset=36)
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["EXT_made_up"],
        "extensionsRequired": ["EXT_made_up"],
        "nodes": [
            {"name": "stretch", "scale": [1, 2, 1], "mesh": 0, "children": [1]},
            {"name": "child", "translation": [10, 0, 0], "mesh": 1},
        ],
        "meshes": [
            {"primitives": [
                {"attributes": {"POSITION": a_pos, "NORMAL": a_n, "TEXCOORD_0": a_uv},
                 "indices": a_ix8, "mode": 5, "material": 0},
                {"attributes": {"POSITION": a_pos}, "indices": a_ix32, "mode": 6, "material": 0},
            ]},
            {"primitives": [{"attributes": {"POSITION": a_tri, "TEXCOORD_1": a_tri_uv1}, "material": 0}]},
        ],
        "materials": [{"alphaMode": "BLEND", "emissiveTexture": {"index": 0, "texCoord": 1}}],
        "textures": [{"source": 0}],
        "images": [{"uri": data_uri(MR, "image/png")}],
        "buffers": [{"byteLength": len(b.data), "uri": data_uri(b.data)}],
        "bufferViews": b.views,
        "accessors": b.accessors,
    }
    return doc


def one_triangle(buffers_before=0):
    """A minimal valid document: one triangle from a data: URI buffer."""
    data = f32(0, 0, 0, 1, 0, 0, 0, 1, 0)
    return {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "buffers": [{"byteLength": len(data), "uri": data_uri(data)}],
        "bufferViews": [{"buffer": 0, "byteLength": len(data)}],
        "accessors": [{"bufferView": 0, "componentType": FLOAT, "count": 3, "type": "VEC3"}],
    }


def dump(name, doc):
    write(name, json.dumps(doc, indent=1) + "\n")


def main():
    write("checker.png", CHECKER)
    write("mr.png", MR)
    doc, data = basic_scene("bin")
    write("basic.bin", data)
    dump("basic.gltf", doc)
    doc, _ = basic_scene("embedded")
    dump("basic_embedded.gltf", doc)
    doc, data = basic_scene("glb")
    write_glb("basic.glb", doc, data)
    dump("layout.gltf", layout_scene())

    # environment from an image: 4x2 RGBE, texel (x, y) = ((x+1)/4, (y+1)/2, 1)
    write("sky.hdr", hdr_rgbe(4, 2, lambda x, y: ((x + 1) / 4.0, (y + 1) / 2.0, 1.0)))
    dump("env_map.gltf", {"asset": {"version": "2.0"},
                          "extensions": {"DR_environment": {"uri": "sky.hdr", "strength": 0.5}}})

    # ---- bad inputs ----
    write("bad_json.gltf", '{"asset": {"version": "2.0"}, "nodes": [{"mesh": 0},\n')

    doc = one_triangle()
    doc["buffers"].append({"byteLength": 36, "uri": "nothere.bin"})
    dump("missing_bin.gltf", doc)

    doc = one_triangle()
    doc["accessors"][0]["count"] = 4          # 48 bytes from a 36-byte bufferView
    dump("accessor_range.gltf", doc)

    doc = one_triangle()
    doc["nodes"].append({"mesh": 1})
    doc["scenes"][0]["nodes"].append(1)
    doc["meshes"].append({"primitives": [{"attributes": {"POSITION": 0}, "mode": 0}]})
    dump("points.gltf", doc)

    doc = one_triangle()
    doc["textures"] = [{"sampler": 0}]
    doc["samplers"] = [{}]
    dump("tex_nosource.gltf", doc)

    doc = one_triangle()
    doc["extensions"] = {"DR_environment": {"uri": "nosky.hdr"}}
    dump("bad_env.gltf", doc)


if __name__ == "__main__":
    main()
