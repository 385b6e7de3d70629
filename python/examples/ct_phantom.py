#!/usr/bin/python3
"""The README's Python example: a CT-like volume written from numpy (an image
stack in Hounsfield units, anisotropic voxels, noise), its bone surface
extracted by pqdc and written as PLY.

    PYTHONPATH=build/python /usr/bin/python3 python/examples/ct_phantom.py bone.ply
    build/bin/pqdc-render bone.ply -o docs/python-ct.png --shading smooth --up 0,0,1 --azimuth 250 --elevation 20 \
        --edges off --width 640 --height 640 --title "bone of a CT-like numpy volume, cut open by mask="
"""
import sys

import numpy as np
import pqdc

# 160 slices of 256 x 256 pixels: 0.7 mm pixels, 1.5 mm slices (volume[slice, row, column]).
z, y, x = np.meshgrid(np.arange(160) * 1.5, np.arange(256) * 0.7, np.arange(256) * 0.7,
                      indexing="ij", sparse=True)
inside = lambda d: 1 / (1 + np.exp(-d / 0.6))          # partial-volume edge, d in mm (> 0 inside)
body = inside(60 - np.hypot((x - 90) / 1.3, y - 90))   # soft tissue
shaft = np.hypot(x - 90 - 0.12 * (z - 120), y - 90)    # a tilted long bone ...
head = np.sqrt((x - 90 - 0.12 * 80) ** 2 + (y - 90) ** 2 + (z - 200) ** 2)  # ... with a round head
cortex = np.maximum(inside(12 - shaft) * inside(shaft - 7) * inside(200 - z), inside(22 - head))
ct = -1000 + 1040 * body + 1100 * cortex * body        # air -1000, tissue 40, bone ~1100 HU
ct = (ct + np.random.default_rng(0).normal(0, 40, ct.shape)).astype(np.float32)

cut = np.broadcast_to((y > 90) | (z > 150), ct.shape)  # mask: open the shaft to show its marrow
mesh = pqdc.extract(ct, isovalue=400, interior="above", axes="zyx", spacing=(0.7, 0.7, 1.5), mask=cut)
print(mesh, f"{mesh.stats['seconds_extract'] + mesh.stats['seconds_convert']:.2f} s")
mesh.write(sys.argv[1] if len(sys.argv) > 1 else "bone.ply")
