#!/usr/bin/python3
"""Writes the small OpenVDB files of tests/cli_media.sh and
tests/test_media_gltf.c. Needs Debian's python3-openvdb (scripts/install-deps.sh
installs it), which only the system interpreter sees, hence /usr/bin/python3.
The outputs are checked in (the tests do not need OpenVDB's Python module);
rerun after changing this or smoke.raw:
  /usr/bin/python3 tests/data/media/make_vdb.py

  smoke.vdb     the 16^3 voxels of smoke.raw as the float grid "density",
                every voxel active (zeros too, so the active bounding box is
                the whole 16^3) at index coordinates (-8..7, 3..18, 100..115)
                with a 0.125 voxel size (drender stretches the active box over
                the medium's box and ignores the transform); before it in the
                file a float grid "temperature" (one voxel) and a vec3 grid
                "velocity", so picking "density" by name is tested
  nofloat.vdb   only a bool grid (OpenImageIO's reader does not open it)
  vec3.vdb      only a vec3 grid
  empty.vdb     a float grid "density" without active voxels
  not-a-vdb.vdb a text file
"""
import os
import struct

import pyopenvdb as vdb

HERE = os.path.dirname(os.path.abspath(__file__))
N = 16
ORIGIN = (-8, 3, 100)


def smoke_grid():
    with open(os.path.join(HERE, "smoke.raw"), "rb") as f:
        values = struct.unpack("<%df" % (N * N * N), f.read())
    g = vdb.FloatGrid(background=0.0)
    g.name = "density"
    g.transform = vdb.createLinearTransform(voxelSize=0.125)
    acc = g.getAccessor()
    for z in range(N):
        for y in range(N):
            for x in range(N):
                acc.setValueOn((ORIGIN[0] + x, ORIGIN[1] + y, ORIGIN[2] + z), values[(z * N + y) * N + x])
    return g


temperature = vdb.FloatGrid()
temperature.name = "temperature"
temperature.getAccessor().setValueOn((0, 0, 0), 5.0)
velocity = vdb.Vec3SGrid()
velocity.name = "velocity"
velocity.getAccessor().setValueOn((1, 2, 3), (1.0, 0.0, 0.0))
vdb.write(os.path.join(HERE, "smoke.vdb"), grids=[temperature, velocity, smoke_grid()])

mask = vdb.BoolGrid()
mask.name = "mask"
mask.getAccessor().setValueOn((0, 0, 0), True)
vdb.write(os.path.join(HERE, "nofloat.vdb"), grids=[mask])
vdb.write(os.path.join(HERE, "vec3.vdb"), grids=[velocity])
empty = vdb.FloatGrid()
empty.name = "density"
vdb.write(os.path.join(HERE, "empty.vdb"), grids=[empty])
with open(os.path.join(HERE, "not-a-vdb.vdb"), "w") as f:
    f.write("this is not an OpenVDB file\n")
