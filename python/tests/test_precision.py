"""The precision a mesh is checked at is the precision it is written at:
pqdc.extract(...).write(path) and pqdc.extract_to_file store what the CLI
stores, free of self-intersections once rounded to float (the Python
module used to check the float64 vertices and then round them, crossing
faces that nearly touched)."""

import json
import os
import subprocess
import warnings

import numpy as np
import pytest

import pqdc


@pytest.fixture(scope="module")
def tools():
    d = os.environ.get("PQDC_BIN_DIR") or os.path.join(os.path.dirname(pqdc.__file__), "..", "..", "bin")
    paths = {name: os.path.join(d, name) for name in ("pqdc", "pqdc-measure")}
    for name, path in paths.items():
        if not os.access(path, os.X_OK):
            pytest.fail(f"{name} not found at {path}: build the apps, or set PQDC_BIN_DIR")
    return paths


def intersecting_pairs(tools, path):
    out = subprocess.run([tools["pqdc-measure"], path], capture_output=True, text=True, check=True).stdout
    return json.loads(out)["self_intersections"]["pair_count"]


def labels_volume(path, seed):
    """Three labels with a little noise: sheets that nearly touch everywhere."""
    import pyopenvdb as vdb
    rng = np.random.default_rng(seed)
    n = int(rng.integers(16, 36))
    a = (rng.integers(0, 3, (n, n, n)) - 0.5 + rng.standard_normal((n, n, n)) * 0.01).astype(np.float32)
    g = vdb.FloatGrid(background=1000.0)
    g.name = "labels"
    g.copyFromArray(a, tolerance=0)
    vdb.write(path, grids=[g])


@pytest.mark.parametrize("seed", [3, 5, 9])  # each gave 1-8 intersecting pairs at float before
def test_float_files_are_the_cli_bytes_and_free_of_intersections(tools, tmp_path, seed):
    volume = str(tmp_path / "labels.vdb")
    labels_volume(volume, seed)
    options = dict(sigma_n=0.0, containment="unconstrained", threads=2)
    cli = tmp_path / "cli.ply"
    subprocess.run([tools["pqdc"], volume, "--sigma-n", "0", "--containment", "none", "--threads", "2", "-q",
                    "-o", str(cli)], check=True)
    written = tmp_path / "extract.ply"
    pqdc.extract(volume, **options).write(written)
    streamed = tmp_path / "streamed.ply"
    pqdc.extract_to_file(volume, streamed, **options)
    assert written.read_bytes() == cli.read_bytes()
    assert streamed.read_bytes() == cli.read_bytes()
    assert intersecting_pairs(tools, str(written)) == 0
    cli_double = tmp_path / "cli-double.ply"
    subprocess.run([tools["pqdc"], volume, "--sigma-n", "0", "--containment", "none", "--threads", "2", "-q",
                    "--precision", "double", "-o", str(cli_double)], check=True)
    written_double = tmp_path / "extract-double.ply"
    pqdc.extract(volume, precision="double", **options).write(written_double)  # writes at double by default
    assert written_double.read_bytes() == cli_double.read_bytes()


def test_a_labels_array_in_adaptive_mode_writes_no_intersections(tools, tmp_path):
    rng = np.random.default_rng(2)
    n = int(rng.integers(12, 40))
    a = (rng.integers(0, 3, (n, n, n)).astype(np.float32) - 0.5 + rng.standard_normal((n, n, n)) * 0.01)
    mesh = pqdc.extract(a.astype(np.float32), adaptive=True, threads=2)
    mesh.write(tmp_path / "labels.ply")
    assert intersecting_pairs(tools, str(tmp_path / "labels.ply")) == 0  # was 8
    decimated = mesh.decimate(target_ratio=0.5, threads=2)
    decimated.write(tmp_path / "decimated.ply")
    assert intersecting_pairs(tools, str(tmp_path / "decimated.ply")) == 0


def test_writing_at_another_precision_than_checked_warns(tmp_path):
    mesh = pqdc.extract(np.pad(np.ones((6, 6, 6), np.float32), 2) - 0.5, interior="above")
    with pytest.warns(RuntimeWarning, match="made free of self-intersections at float precision"):
        mesh.write(tmp_path / "double.ply", precision="double")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mesh.write(tmp_path / "float.ply")
        pqdc.read_mesh(str(tmp_path / "float.ply")).write(tmp_path / "again.ply", precision="double")
    with pytest.raises(pqdc.OptionError, match="precision must be 'float' or 'double'"):
        pqdc.extract(np.zeros((4, 4, 4), np.float32), precision="half")


def test_a_mesh_beyond_floats_range_names_the_argument_to_change(tmp_path):
    i = np.arange(16) - 7.5
    x, y, z = np.meshgrid(i, i, i, indexing="ij")
    mesh = pqdc.extract(np.sqrt(x * x + y * y + z * z) - 5, spacing=1e300, precision="double")
    # The library's message named the CLI's --precision double.
    with pytest.warns(RuntimeWarning), pytest.raises(
            pqdc.InputError, match=r'beyond float\'s range; write it with double precision \(precision="double": PLY'):
        mesh.write(str(tmp_path / "far.ply"), precision="float")
    assert not any(tmp_path.iterdir())
    mesh.write(str(tmp_path / "far.ply"))  # double, as it was made
    assert pqdc.read_mesh(str(tmp_path / "far.ply")).vertices.max() > 1e300


def test_brick_runs_beyond_64_is_refused_in_python_terms(tmp_path):
    with pytest.raises(pqdc.OptionError, match=r"brick_runs must be at most 64 runs \(or None\), got 100"):
        pqdc.extract_to_file("missing.vdb", tmp_path / "o.ply", brick_runs=100)


def test_an_array_placed_far_away_warns_when_float_collapses_it():
    # Meshed in index space and placed afterwards: the library's float check
    # never saw the placed coordinates. At x = 1e6 with 1e-3 spacing float
    # holds one x value: the sphere was written flattened, without a word.
    i = np.arange(32) - 15.5
    x, y, z = np.meshgrid(i, i, i, indexing="ij")
    s = (np.sqrt(x * x + y * y + z * z) - 10).astype(np.float32)
    far = pqdc.extract(s, spacing=1e-3, origin=(1e6, 0, 0))
    assert any("too large (or too small) for float's spacing" in w and 'precision="double"' in w
               for w in far.stats["warnings"])
    assert not pqdc.extract(s, spacing=1e-3, origin=(1e6, 0, 0), precision="double").stats["warnings"]
    assert not pqdc.extract(s, spacing=1e-3, origin=(10, 0, 0)).stats["warnings"]
