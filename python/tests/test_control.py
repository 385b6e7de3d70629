"""Progress, cancellation, exceptions from the callback, Ctrl-C and the GIL."""

import threading
import time

import numpy as np
import pytest

import pqdc
from conftest import run_python, sphere_distance


def gyroid(n, period=10.0):
    x = np.arange(n, dtype=np.float32) * np.float32(2 * np.pi / period)
    s, c = np.sin(x), np.cos(x)
    return (s[:, None, None] * c[None, :, None] + s[None, :, None] * c[None, None, :]
            + s[None, None, :] * c[:, None, None]).astype(np.float32)


def test_progress_is_monotonic_and_reaches_one():
    seen = []
    pqdc.extract(sphere_distance((64, 64, 64), (31.5, 31.5, 31.5), 20.0), progress=seen.append)
    assert len(seen) > 10
    assert all(0.0 <= a <= b <= 1.0 for a, b in zip(seen, seen[1:]))
    assert seen[-1] == 1.0


@pytest.mark.parametrize("stop_at", [0.05, 0.5, 0.95])
def test_cancel_in_every_stage(stop_at):
    seen = []

    def progress(fraction):
        seen.append(fraction)
        return fraction < stop_at

    with pytest.raises(pqdc.CancelledError):
        pqdc.extract(sphere_distance((64, 64, 64), (31.5, 31.5, 31.5), 20.0), progress=progress)
    assert seen[-1] >= stop_at and seen[-1] < 1.0


def test_exception_from_the_callback_propagates_unchanged():
    class Stop(Exception):
        pass

    raised = Stop("from the callback")

    def progress(fraction):
        if fraction > 0.4:
            raise raised

    with pytest.raises(Stop) as e:
        pqdc.extract(sphere_distance((48, 48, 48), (23.5, 23.5, 23.5), 15.0), progress=progress)
    assert e.value is raised
    assert any(frame.name == "progress" for frame in e.traceback)


# (adaptive, the progress fraction after which SIGINT is sent 0.05 s later,
# or None: 0.4 s after the start, without a callback). The adaptive fractions
# aim at its stages: src/adaptive/extract_adaptive.cpp's hermite from 0.1,
# octree 0.3, dual grid 0.45, polygons 0.6, which an array's extraction
# reports as 0.3 + 0.7 f (the conversion takes [0, 0.3]).
ADAPTIVE_STAGES = {"hermite": 0.37, "octree": 0.51, "dual grid": 0.615, "polygons": 0.72}


@pytest.mark.parametrize("adaptive,after", [(False, None), (True, None)] +
                         [(True, f) for f in ADAPTIVE_STAGES.values()],
                         ids=["uniform", "adaptive"] + [f"adaptive-{k}" for k in ADAPTIVE_STAGES])
def test_keyboard_interrupt_cancels_within_a_second(adaptive, after):
    # In a fresh process: SIGINT from a timer thread while the main thread is
    # inside the extraction (single-threaded, several seconds uninterrupted).
    code = f"""
import os, signal, threading, time, numpy as np, pqdc
from test_control import gyroid
v = gyroid(128)
sent, seen, armed = [], [], []
def interrupt():
    sent.append(time.perf_counter())
    os.kill(os.getpid(), signal.SIGINT)
def progress(fraction):
    seen.append(fraction)
    if not armed and fraction >= {after}:
        armed.append(fraction)
        threading.Timer(0.05, interrupt).start()
if {after} is None:
    threading.Timer(0.4, interrupt).start()
start = time.perf_counter()
try:
    pqdc.extract(v, threads=1, adaptive={adaptive}, progress=None if {after} is None else progress)
    print("finished", time.perf_counter() - start, 1.0)
except KeyboardInterrupt:
    print("interrupted", time.perf_counter() - sent[0], seen[-1] if seen else 0.0)
"""
    import os
    here = os.path.dirname(__file__)
    r = run_python(code, {"PYTHONPATH": os.environ.get("PYTHONPATH", "") + os.pathsep + here})
    assert r.returncode == 0, r.stderr
    word, seconds, fraction = r.stdout.split()
    assert word == "interrupted", r.stdout
    assert float(seconds) < 1.0, r.stdout
    if after is not None:
        assert after <= float(fraction) < 1.0, r.stdout


def test_progress_reports_do_not_change_the_adaptive_mesh():
    # Progress chunks the stages' parallel loops; the mesh must not notice.
    volume = gyroid(48)
    plain = pqdc.extract(volume, adaptive=True, threads=2)
    seen = []
    reported = pqdc.extract(volume, adaptive=True, threads=2, progress=seen.append)
    assert len(seen) > 20
    assert all(0.0 <= a <= b <= 1.0 for a, b in zip(seen, seen[1:]))
    assert np.array_equal(plain.vertices, reported.vertices)
    assert np.array_equal(plain.faces, reported.faces)


def test_other_python_threads_run_during_the_extraction():
    # Ticks of another thread that fall outside every progress callback
    # (the only moments the extraction itself runs Python) show the GIL is
    # released while C++ works.
    volume = gyroid(96)
    windows, ticks, running = [], [], threading.Event()
    running.set()

    def ticker():
        while running.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.0005)

    def progress(fraction):
        t0 = time.perf_counter()
        windows.append((t0, t0))
        windows[-1] = (t0, time.perf_counter())

    thread = threading.Thread(target=ticker)
    thread.start()
    try:
        pqdc.extract(volume, threads=1, progress=progress)
    finally:
        running.clear()
        thread.join()
    starts = np.array([w[0] for w in windows])
    ends = np.array([w[1] for w in windows])
    t = np.array([x for x in ticks if starts[0] < x < ends[-1]])
    i = np.searchsorted(starts, t) - 1  # last window starting before the tick
    margin = 0.002
    outside = (t > ends[i] + margin) & ((i + 1 >= len(starts)) | (t < starts[np.minimum(i + 1, len(starts) - 1)] - margin))
    assert outside.sum() > 20, (outside.sum(), len(t), len(windows))
