#!/usr/bin/python3
"""pqdc's Python package against skimage.measure.marching_cubes and pyopenvdb's
convertToPolygons: time, extra peak memory and mesh error against the
analytic surface, on the same volume in the same run.

    PYTHONPATH=build/python /usr/bin/python3 python/bench/bench_python.py [--size 512] [--runs 1]

Every measurement runs in a fresh process: the volume is built slab by slab
(no full-size temporaries), then the peak resident set (VmHWM) is read before
and after the call; "extra" is the difference. Cases:

  sphere   float32 signed distance to a sphere of radius 0.39 n, isovalue 0
  ct       uint16 "CT" volume, n x n x n/2 voxels of 0.5 x 0.5 x 1.0 mm: a
           bright ellipsoid (1000) in air (0), edge blurred over ~1 mm, noise
           sigma 20; isovalue 500, interior above
  levelset pyopenvdb narrow-band level set sphere (radius 0.39 n voxels,
           half width 3): pqdc.extract(grid) vs grid.convertToPolygons()

Mesh error: distance from each vertex (and each triangle's centroid) to the
analytic surface, in voxels of the finest axis (first-order distance for the
ellipsoid).
"""

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np


def peak_rss():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))


def sphere_params(n):
    return np.array([(n - 1) / 2 + 0.13, (n - 1) / 2 - 0.21, (n - 1) / 2 + 0.07]), 0.39 * n


def build_sphere(n):
    c, r = sphere_params(n)
    v = np.empty((n, n, n), np.float32)
    y = np.arange(n) - c[1]
    z = np.arange(n) - c[2]
    yz = y[:, None] ** 2 + z[None, :] ** 2
    for i in range(n):
        v[i] = np.sqrt((i - c[0]) ** 2 + yz) - r
    return v


CT_SPACING = (0.5, 0.5, 1.0)


def ct_params(n):
    extent = np.array([n * CT_SPACING[0], n * CT_SPACING[1], n / 2 * CT_SPACING[2]])
    return extent / 2 + [0.11, -0.17, 0.05], extent * [0.36, 0.30, 0.40]


def build_ct(n):
    centre, axes = ct_params(n)
    shape = (n, n, n // 2)
    rng = np.random.default_rng(1)
    v = np.empty(shape, np.uint16)
    y = (np.arange(shape[1]) * CT_SPACING[1] - centre[1]) / axes[1]
    z = (np.arange(shape[2]) * CT_SPACING[2] - centre[2]) / axes[2]
    yz = y[:, None] ** 2 + z[None, :] ** 2
    for i in range(shape[0]):
        q = np.sqrt(((i * CT_SPACING[0] - centre[0]) / axes[0]) ** 2 + yz)
        d = (q - 1) * axes.min()  # ~ distance in mm
        slab = 1000 / (1 + np.exp(d / 0.5)) + 20 + rng.normal(0, 20, q.shape)
        v[i] = np.clip(slab, 0, 65535).astype(np.uint16)
    return v


def sphere_error(points, n):
    c, r = sphere_params(n)
    return np.linalg.norm(points - c, axis=1) - r


def ct_error(points, n):
    centre, axes = ct_params(n)
    p = (points - centre) / axes
    q = np.sqrt((p**2).sum(1))
    grad = p / axes / q[:, None]
    return (q - 1) / np.linalg.norm(grad, axis=1) / min(CT_SPACING)  # in finest voxels


def run_method(case, method, n):
    """Returns (vertices, triangles, quads) in world units and the source's size."""
    import pqdc
    if case == "levelset":
        import pyopenvdb as vdb
        c, r = sphere_params(n)
        source = vdb.createLevelSetSphere(radius=r, center=tuple(c), voxelSize=1.0, halfWidth=3.0)
        nbytes = source.memUsage()
    else:
        source = build_sphere(n) if case == "sphere" else build_ct(n)
        nbytes = source.nbytes
    pqdc.extract(np.zeros((4, 4, 4), np.float32) - 1)  # load libraries before the baseline
    if method == "pyopenvdb":
        import pyopenvdb as vdb  # noqa: F401
    if method == "skimage":
        import skimage.measure  # noqa: F401
    base = peak_rss()
    t0 = time.perf_counter()
    if method.startswith("pqdc"):
        if case == "ct":
            m = pqdc.extract(source, isovalue=500, interior="above", spacing=CT_SPACING)
        else:
            m = pqdc.extract(source)
        if method == "pqdc+normals":  # sampled on first access; skimage always computes them
            m.vertex_normals
        out = (m.vertices, m.faces, np.zeros((0, 4), np.int64))
    elif method == "skimage":
        if case == "ct":
            v, f, _, _ = skimage.measure.marching_cubes(source, 500, spacing=CT_SPACING)
        else:
            v, f, _, _ = skimage.measure.marching_cubes(source, 0.0, gradient_direction="ascent")
        out = (v, f, np.zeros((0, 4), np.int64))
    else:  # pyopenvdb: arrays go through copyFromArray first, as a numpy user must
        import pyopenvdb as vdb
        grid = source
        if case != "levelset":
            grid = vdb.FloatGrid(background=0.0 if case == "ct" else float(source.max()))
            grid.copyFromArray(source.astype(np.float32) if source.dtype != np.float32 else source)
            if case == "ct":
                grid.transform = vdb.createLinearTransform(
                    [[CT_SPACING[0], 0, 0, 0], [0, CT_SPACING[1], 0, 0], [0, 0, CT_SPACING[2], 0], [0, 0, 0, 1]])
        points, tris, quads = grid.convertToPolygons(isovalue=500.0 if case == "ct" else 0.0)
        out = (points, tris, quads)
    seconds = time.perf_counter() - t0
    extra = peak_rss() - base
    return out, seconds, extra, nbytes


def worker(case, method, n):
    (v, f, q), seconds, extra, nbytes = run_method(case, method, n)
    v = np.asarray(v, np.float64)
    err = sphere_error if case != "ct" else ct_error
    e = np.abs(err(v, n))
    tri = np.concatenate([np.asarray(f, np.int64).reshape(-1, 3),
                          np.asarray(q, np.int64).reshape(-1, 4)[:, [0, 1, 2]],
                          np.asarray(q, np.int64).reshape(-1, 4)[:, [0, 2, 3]]])
    ec = np.abs(err(v[tri].mean(axis=1), n)) if len(tri) else np.zeros(1)
    print(json.dumps({"case": case, "method": method, "seconds": seconds, "extra": extra, "source": nbytes,
                      "vertices": len(v), "faces": int(len(f) + len(q)), "v_rms": float(np.sqrt(np.mean(e**2))),
                      "v_max": float(e.max()), "c_rms": float(np.sqrt(np.mean(ec**2)))}))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--runs", type=int, default=1, help="best time of this many processes per method")
    ap.add_argument("--cases", default="sphere,ct,levelset")
    ap.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        return worker(a.worker[0], a.worker[1], a.size)
    methods = {"sphere": ["pqdc", "pqdc+normals", "skimage", "pyopenvdb"],
               "ct": ["pqdc", "pqdc+normals", "skimage", "pyopenvdb"],
               "levelset": ["pqdc", "pyopenvdb"]}
    print(f"| case ({a.size}) | method | seconds | extra peak MiB | extra / source | vertices | faces | "
          f"vertex error rms / max | centroid rms |")
    print("|---|---|---|---|---|---|---|---|---|")
    for case in a.cases.split(","):
        results = {}
        for method in methods[case]:
            best = None
            for _ in range(a.runs):
                r = subprocess.run([sys.executable, __file__, "--size", str(a.size), "--worker", case, method],
                                   capture_output=True, text=True, env=os.environ)
                if r.returncode != 0:
                    sys.exit(f"bench_python: {case}/{method} failed:\n{r.stderr}")
                res = json.loads(r.stdout)
                if best is None or res["seconds"] < best["seconds"]:
                    best = res
            results[method] = best
            b = best
            print(f"| {case} | {method} | {b['seconds']:.2f} | {b['extra'] / 2**20:.0f} | "
                  f"{b['extra'] / b['source']:.2f} | {b['vertices']} | {b['faces']} | "
                  f"{b['v_rms']:.4f} / {b['v_max']:.3f} | {b['c_rms']:.4f} |", flush=True)
        p = results["pqdc"]
        for peer, r in results.items():
            if not peer.startswith("pqdc"):
                print(f"|   | {peer} time / pqdc time | {r['seconds'] / p['seconds']:.2f} | | | | | | |")


if __name__ == "__main__":
    main()
