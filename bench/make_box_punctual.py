#!/usr/bin/env python3
"""Writes bench part r's scenes: the peer's Cornell box
(../shared/bench/peer-cornell-box.gltf) lit by a KHR_lights_punctual light
instead of its area light, as Blender exports and many glTF assets are: the
light's quad stays (a grey panel: its emission is taken off) and a point
or spot light of its colour shines from just below it, or a directional
light in through the open front (radiometric intensities, DR_units). The box's surfaces and camera are
unchanged.

    make_box_punctual.py PEER.gltf OUT.gltf point|spot|directional

Standard library only."""
import json
import sys

POSITION = [0.0, 0.9, 0.0]   # just below the ceiling's lamp
COLOUR = [1.0, 0.7607168107902321, 0.36730135421765375]
# radiometric (DR_units): W/sr for point and spot, W/m^2 for directional,
# about the area light's power into the room
INTENSITY = {"point": 25.0, "spot": 40.0, "directional": 4.0}
# the node's rotation (its -Z is the light's direction): point and spot
# down (-90 degrees about X); the directional light in through the box's
# open front, 17 degrees downwards (the ceiling shades the box from above)
ROTATION = {"point": [-0.7071068, 0.0, 0.0, 0.7071068], "spot": [-0.7071068, 0.0, 0.0, 0.7071068],
            "directional": [-0.1453, 0.0, 0.0, 0.9894]}


def main():
    if len(sys.argv) != 4 or sys.argv[3] not in INTENSITY:
        sys.exit(__doc__)
    peer, out, kind = sys.argv[1:]
    with open(peer) as f:
        g = json.load(f)
    lamp = next(m for m in g["materials"] if m.get("name") == "light")
    lamp.pop("emissiveFactor", None)
    lamp.get("extensions", {}).pop("KHR_materials_emissive_strength", None)
    light = {"type": kind, "color": COLOUR, "intensity": INTENSITY[kind]}
    if kind == "spot":
        light["spot"] = {"innerConeAngle": 0.6, "outerConeAngle": 1.0}
    g.setdefault("extensions", {})["KHR_lights_punctual"] = {"lights": [light]}
    g["extensions"]["DR_units"] = {"lights": "radiometric"}
    used = g.setdefault("extensionsUsed", [])
    for ext in ("KHR_lights_punctual", "DR_units"):
        if ext not in used:
            used.append(ext)
    g["nodes"].append({"name": "punctual", "translation": POSITION, "rotation": ROTATION[kind],
                       "extensions": {"KHR_lights_punctual": {"light": 0}}})
    g["scenes"][g.get("scene", 0)]["nodes"].append(len(g["nodes"]) - 1)
    # (the peer's buffer is inline: OUT can go anywhere)
    if any(not b.get("uri", "data:").startswith("data:") for b in g.get("buffers", [])):
        sys.exit("make_box_punctual.py: %s has a buffer in a file of its own; expected inline data URIs" % peer)
    with open(out, "w") as f:
        json.dump(g, f)


if __name__ == "__main__":
    main()
