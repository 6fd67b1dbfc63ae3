#!/usr/bin/env python3
"""Writes the small media scenes used by tests/cli_media.sh and make bench
(stdlib only). The outputs are checked in; rerun after changing this:
  python3 tests/data/media/make_scenes.py

  smoke.gltf        a closed cube [-1,1]^3 bounding a DR_medium density grid
                    (smoke.raw, 16^3 float32: a soft blob, empty near the
                    faces) over a grey floor, lit by a constant DR_environment
                    and a point light; camera 0 looks at it
  smoke-empty.gltf  the same with an all-zero grid (empty.raw): the optimize
                    test grows the blob back from nothing
  coarse.gltf, coarse-empty.gltf
                    the same with a 4^3 grid (one majorant cell): the
                    blob, and all zeros
  fog-global.gltf   coarse.gltf inside an unbounded global fog (DR_medium at
                    the document root): the camera and the light are in it
  fog-dense.gltf    a hard case: extinction 1e4, 1e3, 1e2 (1/m), albedo 0.999
  fog-khr.gltf      the cube as a homogeneous KHR_materials_volume medium
                    (transmission 1, ior 1, volume_scatter albedo)
  glass-fog.gltf    fog-khr.gltf behind a smooth dielectric boundary
                    (KHR_materials_ior 1.5): a glass cube of fog
  smoke-vdb.gltf    smoke.gltf with the grid read from smoke.vdb (written by
                    make_vdb.py: the same voxels as an OpenVDB float grid)
"""
import base64
import json
import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
N = 16


def blob(x, y, z, n=N):
    c = [(i + 0.5) / n * 2 - 1 for i in (x, y, z)]
    r = math.sqrt((c[0] - 0.15) ** 2 + (c[1] + 0.1) ** 2 + c[2] ** 2)
    d = max(0.0, 1.0 - r / 0.7)
    return 3.0 * d * (0.75 + 0.25 * math.sin(7 * c[0]) * math.cos(5 * c[1]))


def write_grid(name, f, n=N):
    with open(os.path.join(HERE, name), "wb") as out:
        for z in range(n):
            for y in range(n):
                for x in range(n):
                    out.write(struct.pack("<f", f(x, y, z)))


def scene(material_ext, name, global_medium=None):
    cube = [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]
    cube_idx = [0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4, 3, 7, 6, 3, 6, 2, 0, 4, 7, 0, 7, 3, 1, 2, 6,
                1, 6, 5]
    floor = [(-4, -1.2, -4), (4, -1.2, -4), (4, -1.2, 4), (-4, -1.2, 4)]
    floor_idx = [0, 2, 1, 0, 3, 2]
    pos = b"".join(struct.pack("<3f", *p) for p in cube + floor)
    idx = b"".join(struct.pack("<H", i) for i in cube_idx) + b"".join(struct.pack("<H", i) for i in floor_idx)
    buf = pos + idx
    doc = {
        "asset": {"version": "2.0", "generator": "tests/data/media/make_scenes.py"},
        "extensionsUsed": sorted(set(["DR_environment", "DR_units", "KHR_lights_punctual"] + list(material_ext.keys()))),
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "nodes": [{"mesh": 0, "name": "smoke"}, {"mesh": 1, "name": "floor"},
                  {"camera": 0, "translation": [0.5, 0.6, 4.2],
                   "rotation": [-0.0695, 0.0581, 0.0041, 0.9959]},
                  {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [2, 3, 2]}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.05, "aspectRatio": 1.0}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]},
                   {"primitives": [{"attributes": {"POSITION": 2}, "indices": 3, "material": 1}]}],
        "materials": [{"name": "smoke", "extensions": material_ext},
                      {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1],
                                                                 "metallicFactor": 0, "roughnessFactor": 1}}],
        "buffers": [{"byteLength": len(buf),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 96},
                        {"buffer": 0, "byteOffset": 144, "byteLength": 72},
                        {"buffer": 0, "byteOffset": 96, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 216, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
                       "min": [-1, -1, -1], "max": [1, 1, 1]},
                      {"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"},
                      {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [-4, -1.2, -4], "max": [4, -1.2, 4]},
                      {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}],
        "extensions": {"DR_environment": {"color": [0.5, 0.6, 0.8]},
                       "DR_units": {"lights": "radiometric"},   # the point light's 40 is W/sr
                       "KHR_lights_punctual": {"lights": [{"type": "point", "color": [1, 0.9, 0.8],
                                                           "intensity": 40}]}},
    }
    if global_medium:
        doc["extensions"]["DR_medium"] = global_medium
        doc["extensionsUsed"] = sorted(doc["extensionsUsed"] + ["DR_medium"])
    with open(os.path.join(HERE, name), "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")


def dr_medium(uri, n=N):
    return {"DR_medium": {"extinction": [4, 4, 4], "albedo": [0.85, 0.8, 0.75], "g": 0.2,
                          "density": {"uri": uri, "resolution": [n, n, n]}}}


def dr_medium_vdb(uri):
    return {"DR_medium": {"extinction": [4, 4, 4], "albedo": [0.85, 0.8, 0.75], "g": 0.2,
                          "density": {"uri": uri}}}


write_grid("smoke.raw", blob)
write_grid("empty.raw", lambda x, y, z: 0.0)
scene(dr_medium("smoke.raw"), "smoke.gltf")
scene(dr_medium("empty.raw"), "smoke-empty.gltf")
scene(dr_medium_vdb("smoke.vdb"), "smoke-vdb.gltf")
write_grid("coarse.raw", lambda x, y, z: 0.6 * blob(x, y, z, 4), 4)
write_grid("coarse-empty.raw", lambda x, y, z: 0.0, 4)
scene(dr_medium("coarse.raw", 4), "coarse.gltf")
scene(dr_medium("coarse-empty.raw", 4), "coarse-empty.gltf")
scene({"DR_medium": {"extinction": [1e4, 1e3, 1e2], "albedo": [0.999, 0.999, 0.999], "g": 0.5}}, "fog-dense.gltf")
scene(dr_medium("coarse.raw", 4), "fog-global.gltf",
      {"extinction": [0.15, 0.2, 0.3], "albedo": [0.9, 0.9, 0.9], "g": 0.4})
scene({"KHR_materials_volume": {"thicknessFactor": 1, "attenuationDistance": 1.5,
                                "attenuationColor": [0.6, 0.7, 0.8]},
       "KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1},
       "KHR_materials_volume_scatter": {"multiscatterColor": [0.9, 0.9, 0.9], "scatterAnisotropy": 0.3}},
      "fog-khr.gltf")
scene({"KHR_materials_volume": {"thicknessFactor": 1, "attenuationDistance": 1.5,
                                "attenuationColor": [0.6, 0.7, 0.8]},
       "KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1.5},
       "KHR_materials_volume_scatter": {"multiscatterColor": [0.9, 0.9, 0.9], "scatterAnisotropy": 0.3}},
      "glass-fog.gltf")
