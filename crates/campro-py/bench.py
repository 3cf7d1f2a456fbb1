"""The Python call against the Rust work it wraps, in one run (docs/python.md, "Speed").

    python crates/campro-py/bench.py [--runs 31] [--json]

Rows: a 1920x1080 frame tiled from a real COCO photo (../shared, else a synthetic scene),
timed inside Rust (`bench_capture`: the same call, no arrays around it) and through
`Camera.capture`; the overhead is their difference as a share of the frame time. Then a
batch of 16 frames through one call against 16 calls, and the CPU time over wall time of
the batch (2.0 = both cores of a two-core machine busy). Medians; a benchmark, not a test.
"""

import argparse
import json
import os
import pathlib
import statistics
import time

import numpy as np

import campro


def frame(w=1920, h=1080):
    shared = os.environ.get("CAMPRO_SHARED") or str(pathlib.Path(__file__).resolve().parents[3] / "shared")
    images = pathlib.Path(shared) / "data" / "coco-person" / "images"
    if images.is_dir():
        photo = campro.read(sorted(images.glob("*.jpg"))[0])
        reps = (-(-h // photo.shape[0]), -(-w // photo.shape[1]), 1)
        return np.ascontiguousarray(np.tile(photo, reps)[:h, :w]), "COCO photo tiled"
    y, x = np.mgrid[0:h, 0:w]
    scene = np.stack([(x * 255 // w), (y * 255 // h), ((x + y) * 255 // (w + h))], axis=2).astype(np.uint8)
    return scene, "synthetic gradients"


def median_time(f, runs):
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=101)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    cam = campro.Camera("campro-omega-0.5")
    img, source = frame()
    cam.capture(img)  # warm: tables, pages, threads
    # Interleaved, so that the machine's drift (these machines are shared) falls on both.
    rusts, pythons = [], []
    for _ in range(a.runs):
        rusts += cam._native.bench_capture(img, 1)
        t = time.perf_counter()
        cam.capture(img)
        pythons.append(time.perf_counter() - t)
    rust, python = statistics.median(rusts), statistics.median(pythons)
    batch = np.stack([img] * 16)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    one_call = median_time(lambda: cam.capture(batch), max(3, a.runs // 10))
    busy = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
    many_calls = median_time(lambda: [cam.capture(f) for f in batch], max(3, a.runs // 10))
    rows = {
        "frame": "1920x1080, " + source,
        "cores": os.cpu_count(),
        "rust_ms": rust * 1e3,
        "python_ms": python * 1e3,
        "overhead_pct": (python - rust) / rust * 100,
        "batch16_ms": one_call * 1e3,
        "singles16_ms": many_calls * 1e3,
        "batch16_cpu_per_wall": busy,
    }
    if a.json:
        print(json.dumps(rows))
        return
    print(f"frame: {rows['frame']}, {rows['cores']} cores, medians of {a.runs}")
    print(f"| capture inside Rust | {rows['rust_ms']:.2f} ms |")
    print(f"| Camera.capture (Python) | {rows['python_ms']:.2f} ms | overhead {rows['overhead_pct']:+.1f}% |")
    print(f"| batch of 16, one call | {rows['batch16_ms']:.1f} ms | CPU/wall {busy:.2f} |")
    print(f"| 16 single calls | {rows['singles16_ms']:.1f} ms |")


if __name__ == "__main__":
    main()
