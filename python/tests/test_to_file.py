"""pqdc.extract_to_file streams the in-core mesh's bytes from .vdb files and
brick stores (pqdc.split_to_store), and fails clearly, leaving no file."""

import os

import numpy as np
import pytest

import pqdc


def volume(source_dir, name):
    return os.path.join(source_dir, "volumes", name)


def in_core_bytes(source, path, **options):
    pqdc.extract(source, **options).write(path)
    with open(path, "rb") as f:
        return f.read()


@pytest.mark.parametrize("name", ["armadillo.vdb", "fandisk.vdb", "figure3.vdb"])
@pytest.mark.parametrize("options", [{}, {"faces": "quads", "normals": "sharp"}, {"sigma_n": 0.0}])
def test_streamed_file_is_the_in_core_bytes(source_dir, tmp_path, name, options):
    source = volume(source_dir, name)
    expected = in_core_bytes(source, str(tmp_path / "in_core.ply"), **options)
    for brick_size, runs in ((128, 1), (128, 3), (256, None)):
        out = tmp_path / f"streamed-{brick_size}-{runs}.ply"
        stats = pqdc.extract_to_file(source, out, brick_size=brick_size, brick_runs=runs, **options)
        assert out.read_bytes() == expected, (brick_size, runs)
        assert stats["points_written"] > 1000
        assert stats["triangles_written"] + stats["quads_written"] > 1000
        assert stats["mode"] == "uniform, brick by brick"
    # Only the outputs: the scratch files are gone.
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["in_core.ply"] + [f"streamed-{b}-{r}.ply" for b, r in ((128, 1), (128, 3), (256, None))])


def test_a_brick_store_meshes_like_its_source(source_dir, tmp_path):
    source = volume(source_dir, "armadillo.vdb")
    written = pqdc.split_to_store(source, tmp_path / "arm.bricks", brick_size=128)
    assert written["bricks"] > 1 and written["leaves"] > 100
    expected = in_core_bytes(source, str(tmp_path / "in_core.obj"))
    stats = pqdc.extract_to_file(tmp_path / "arm.bricks", tmp_path / "store.obj", brick_size=128)
    assert (tmp_path / "store.obj").read_bytes() == expected
    assert stats["grid"] == pqdc.extract(source).stats["grid"] and stats["interior"] == "below"
    # pqdc.extract meshes the store too (it said the store was incomplete).
    in_memory = pqdc.extract(tmp_path / "arm.bricks")
    assert np.array_equal(in_memory.vertices, pqdc.extract(source).vertices)


def test_double_precision_and_region_options(source_dir, tmp_path):
    source = volume(source_dir, "fandisk.vdb")
    box = (-1.0, -1.0, -1.0, 0.2, 0.3, 1.0)
    pqdc.extract_to_file(source, tmp_path / "double.ply", bbox=box, precision="double", brick_size=128)
    data = (tmp_path / "double.ply").read_bytes()
    assert b"property double x" in data
    whole = pqdc.extract_to_file(source, tmp_path / "whole.ply")
    part = pqdc.extract_to_file(source, tmp_path / "part.ply", bbox=box)
    assert 0 < part["points_written"] < whole["points_written"]


def test_errors_are_clear_and_leave_no_file(source_dir, tmp_path):
    source = volume(source_dir, "sphere.vdb")
    out = tmp_path / "out.ply"
    with pytest.raises(pqdc.InputError, match=r"no/such\.vdb"):
        pqdc.extract_to_file("no/such.vdb", out)
    with pytest.raises(pqdc.InputError, match="nope"):
        pqdc.extract_to_file(source, out, grid="nope")
    with pytest.raises(pqdc.OptionError, match="brick_size"):
        pqdc.extract_to_file(source, out, brick_size=100)
    with pytest.raises(pqdc.OptionError, match="precision"):
        pqdc.extract_to_file(source, out, precision="half")
    with pytest.raises(pqdc.OptionError, match=r"out\.xyz"):
        pqdc.extract_to_file(source, tmp_path / "out.xyz")
    with pytest.raises(pqdc.WriteError, match="missing"):
        pqdc.extract_to_file(source, tmp_path / "missing" / "out.ply")
    with pytest.raises(TypeError, match="path of a .vdb file or a brick store"):
        pqdc.extract_to_file(object(), out)
    store = tmp_path / "s.bricks"
    pqdc.split_to_store(source, store, brick_size=128)
    with pytest.raises(pqdc.InputError, match="not 'other'"):
        pqdc.extract_to_file(store, out, grid="other")
    with pytest.raises(pqdc.Error, match="s.bricks"):
        pqdc.split_to_store(source, store)  # already holds a store
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.bricks"]


def test_cancelling_leaves_no_file(source_dir, tmp_path):
    out = tmp_path / "out.ply"
    with pytest.raises(pqdc.CancelledError):
        pqdc.extract_to_file(volume(source_dir, "armadillo.vdb"), out, brick_size=128, progress=lambda f: f < 0.3)
    assert list(tmp_path.iterdir()) == []


def test_a_cancelled_split_leaves_no_brick_files(source_dir, tmp_path):
    source = volume(source_dir, "armadillo.vdb")
    seen = []

    def stop_halfway(fraction):
        seen.append(fraction)
        return fraction < 0.5

    with pytest.raises(pqdc.CancelledError, match="cancelled"):
        pqdc.split_to_store(source, tmp_path / "new.bricks", brick_size=128, progress=stop_halfway)
    assert seen[0] == 0.0 and 0.5 <= seen[-1] < 1.0 and seen == sorted(seen)
    assert list(tmp_path.iterdir()) == []  # the directory it made is gone too
    existing = tmp_path / "existing"
    existing.mkdir()
    with pytest.raises(pqdc.CancelledError):
        pqdc.split_to_store(source, existing, brick_size=128, progress=lambda f: f < 0.5)
    assert existing.is_dir() and list(existing.iterdir()) == []  # kept, emptied
    with pytest.raises(TypeError, match="progress"):
        pqdc.split_to_store(source, tmp_path / "x.bricks", progress=3)
    fractions = []
    written = pqdc.split_to_store(source, tmp_path / "whole.bricks", brick_size=128, progress=fractions.append)
    assert written["bricks"] > 1 and fractions[0] == 0.0 and fractions[-1] == 1.0
