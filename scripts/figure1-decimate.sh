#!/usr/bin/env bash
# The Figure 1 experiment of Trettner & Kobbelt 2020 with pqdc-decimate: a
# CAD-like box meshed by dual contouring, Gaussian noise (0.4 voxel along the
# normal) on the half with x > 0 only, then 85% of the faces removed with
# near-classical quadrics (sigma_position 1e-4 voxel: the minimizer falls back
# to the pseudo-inverse, as classical QEM) and with probabilistic triangle
# quadrics (sigma_position 0.3 voxel). Writes docs/decimate-figure1.png.
#   scripts/figure1-decimate.sh [BUILD_DIR]   (default: build)
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$here/build}"
bin="$build/bin"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$bin/pqdc" --procedural box --resolution 64 -o "$work/box.off" --quiet
/usr/bin/python3 - "$work/box.off" "$work/noisy.off" <<'PY'
import sys
import numpy as np
lines = [l for l in open(sys.argv[1]).read().split("\n") if l and not l.startswith("#")]
assert lines[0].strip() == "OFF"
nv, nf, _ = map(int, lines[1].split())
v = np.array([list(map(float, l.split())) for l in lines[2:2 + nv]])
f = np.array([list(map(int, l.split()))[1:4] for l in lines[2 + nv:2 + nv + nf]])
n = np.zeros_like(v)
fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
for k in range(3):
    np.add.at(n, f[:, k], fn)
n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
edge = np.mean(np.linalg.norm(v[f[:, 0]] - v[f[:, 1]], axis=1))  # ~ one voxel
rng = np.random.default_rng(1)
side = v[:, 0] > np.median(v[:, 0])
v[side] += n[side] * rng.normal(0.0, 0.4 * edge, size=(side.sum(), 1))
with open(sys.argv[2], "w") as out:
    out.write("OFF\n%d %d 0\n" % (nv, nf))
    for p in v:
        out.write("%.17g %.17g %.17g\n" % tuple(p))
    for t in f:
        out.write("3 %d %d %d\n" % tuple(t))
PY
"$bin/pqdc-decimate" "$work/noisy.off" -o "$work/classical.ply" --target-ratio 0.15 --sigma-position 1e-4 --quiet
"$bin/pqdc-decimate" "$work/noisy.off" -o "$work/probabilistic.ply" --target-ratio 0.15 --sigma-position 0.3 --quiet
view=(--width 640 --height 560 --azimuth 35 --elevation 25)
"$bin/pqdc-render" "$work/noisy.off" -o "$work/a.png" "${view[@]}" --title "input: noisy where x > 0"
"$bin/pqdc-render" "$work/classical.ply" -o "$work/b.png" "${view[@]}" --title "15%, near-classical quadrics"
"$bin/pqdc-render" "$work/probabilistic.ply" -o "$work/c.png" "${view[@]}" --title "15%, probabilistic triangle quadrics"
/usr/bin/python3 - "$work" "$here/docs/decimate-figure1.png" <<'PY'
import sys
import matplotlib.image as mpimg
import numpy as np
w = sys.argv[1]
img = np.hstack([mpimg.imread(w + "/%s.png" % k) for k in "abc"])
mpimg.imsave(sys.argv[2], img)
PY
echo "wrote $here/docs/decimate-figure1.png"
