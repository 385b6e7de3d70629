#!/usr/bin/env python3
"""Writes the seed inputs (seed_*) of tests/fuzz/corpus; the layout is in
fuzz_extract_core.hpp. Deterministic; rerun after changing the layout.
found_* are 40 of the ~820 inputs a 6-minute pqdc_fuzz_extract run added
for new coverage (libFuzzer -merge=1), kept as regression inputs."""
import math
import os
import random

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus")


def code(v):
    """int8 / 16 value code, clamped away from the special codes."""
    c = max(-127, min(127, int(round(v * 16))))
    c = 0x7f if c == -128 else c
    b = c & 0xff
    return 0x79 if 0x80 <= b <= 0x88 else b


def grid(flags, cls, n, bg, xf, rot, tiles, active, values):
    out = bytearray([flags, cls, n[0] - 1, n[1] - 1, n[2] - 1, bg, xf, rot, len(tiles)])
    for t in tiles:
        out += bytes(t)
    count = n[0] * n[1] * n[2]
    bits = bytearray((count + 7) // 8)
    for i in range(count):
        if active(i):
            bits[i // 8] |= 1 << (i % 8)
    out += bits
    out += bytes(values(i) for i in range(count))
    return bytes(out)


def coords(i, n):
    return i % n[0], (i // n[0]) % n[1], i // (n[0] * n[1])


def field(n, f):
    return lambda i: code(f(*coords(i, n)))


def main():
    os.makedirs(HERE, exist_ok=True)
    rng = random.Random(6)
    n = (10, 10, 10)
    sphere = lambda x, y, z: math.sqrt((x - 4.6) ** 2 + (y - 4.3) ** 2 + (z - 4.8) ** 2) - 3.2
    planes = lambda x, y, z: abs(x - 4.5) - 0.3  # two sheets one cell apart
    seeds = {
        "sphere": grid(0x06, 0x80, n, code(3), 0, 0, [], lambda i: True, field(n, sphere)),
        "sphere_quads_sigma0": grid(0x10, 0x80, n, code(3), 0, 0, [], lambda i: True, field(n, sphere)),
        "sphere_unconstrained_inf": grid(0x2c, 0x80, n, code(3), 0, 0, [], lambda i: True, field(n, sphere)),
        "fog_above": grid(0x86, 0x89, n, code(0), 0, 0, [], lambda i: True,
                          field(n, lambda x, y, z: max(0.0, min(1.0, 0.5 - sphere(x, y, z) / 4)))),
        "double_nan": grid(0x07, 0x80, n, code(3), 0, 0, [], lambda i: True,
                           lambda i: 0x80 if i % 37 == 0 else field(n, sphere)(i)),
        "tiles": grid(0x06, 0x80, (9, 9, 9), code(2), 0, 0,
                      [(0x15, code(-2), 1), (0x2a, code(2), 1), (0x00, code(-2), 0)], lambda i: True,
                      field((9, 9, 9), lambda x, y, z: x - 3.5)),
        "mirror_far": grid(0x06, 0x80, n, code(3), 0xc5, 0x9d, [], lambda i: True, field(n, sphere)),
        "tiny_voxels": grid(0x06, 0x80, n, code(3), 0x80, 0x11, [], lambda i: True, field(n, sphere)),
        "two_sheets": grid(0x06, 0x80, n, code(3), 0, 0, [], lambda i: True, field(n, planes)),
        "checkerboard": grid(0x06, 0x80, (6, 6, 6), code(1), 0, 0, [], lambda i: True,
                             lambda i: code(0.5 if sum(coords(i, (6, 6, 6))) % 2 else -0.5)),
        "holes": grid(0x06, 0x80, n, code(3), 0, 0, [], lambda i: (i * 7919) % 11 != 0, field(n, sphere)),
        "specials": grid(0x0e, 0x80, (5, 5, 5), 0x81, 0, 0, [], lambda i: True,
                         lambda i: [0x80, 0x81, 0x82, 0x83, 0x84, 0x85, 0x86, 0x87, code(-1), code(1)][i % 10]),
        "noise": grid(0x16, 0x80, n, code(2), 0, 0, [], lambda i: rng.random() < 0.9,
                      lambda i: code(sphere(*coords(i, n)) + rng.uniform(-1.5, 1.5))),
    }
    for name, data in seeds.items():
        with open(os.path.join(HERE, "seed_" + name), "wb") as f:
            f.write(data)


if __name__ == "__main__":
    main()
