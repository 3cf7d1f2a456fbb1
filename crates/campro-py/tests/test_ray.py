"""campro on Ray Data, on a local Ray instance (ray.init(num_cpus=2)): one scenario per test."""

import json
import os
import pathlib
import re
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import campro

if os.environ.get("CI") == "true":
    import ray  # CI installs Ray: its absence is a failure there
else:
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'campro[ray]')")

import campro.ray  # noqa: E402
from conftest import colour_photos  # noqa: E402

PRESET = "campro-omega-0.5"
N = 200


@pytest.fixture(scope="module")
def local_ray():
    # The workers cannot import this test module: its classes travel by value.
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    """200 real COCO photos in two folders, plus three corrupt files and one grey photo."""
    files = colour_photos(N)
    src = tmp_path_factory.mktemp("photos")
    for i, p in enumerate(files):
        d = src / ("a" if i % 2 else "b")
        d.mkdir(exist_ok=True)
        shutil.copyfile(p, d / p.name)
    (src / "bad").mkdir()
    (src / "bad" / "truncated.jpg").write_bytes(files[0].read_bytes()[:300])
    (src / "bad" / "noise.png").write_bytes(os.urandom(5000))
    (src / "bad" / "empty.jpg").write_bytes(b"")
    grey = campro.read(files[1]).mean(axis=2, keepdims=True).astype(np.uint8).repeat(3, axis=2)
    campro.write(src / "bad" / "grey.png", grey)
    return src


def outputs(folder):
    return sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file())


def verify_all(folder):
    """Every output's record verifies against the output as it is (`campro check --record`'s rule)."""
    cam = campro.Camera(PRESET)
    made = [p for p in folder.rglob("*") if p.is_file() and not p.name.endswith(".campro.json")]
    for out in made:
        record = json.loads((out.parent / (out.name + ".campro.json")).read_text())
        import hashlib

        assert hashlib.sha256(out.read_bytes()).hexdigest() == record["output"]["sha256"], out
        assert record["preset"]["sha256"] == cam._native.preset_sha256
    return len(made)


def test_protect_on_numpy_batches_gives_rows_with_their_status(local_ray, photos):
    files = sorted((photos / "a").glob("*.jpg"))[:6]
    images = [campro.read(p) for p in files] + [np.zeros((4, 4, 4), np.uint8), campro.read(photos / "bad" / "grey.png")]
    ds = ray.data.from_items([{"image": im} for im in images])
    out = ds.map_batches(
        campro.ray.Protect, fn_constructor_kwargs={"preset": PRESET}, concurrency=2, batch_size=4, batch_format="numpy"
    ).take_all()
    assert [r["campro_status"] for r in out] == ["ok"] * 6 + ["error", "refused"]
    assert "H x W x 3" in out[6]["campro_error"] and "grey" in out[7]["campro_error"]
    cam = campro.Camera(PRESET)
    for im, r in zip(images[:6], out[:6]):
        assert np.array_equal(r["image"], cam.capture(im))
        assert r["campro_preset_sha256"] == cam._native.preset_sha256


def test_the_command_writes_what_simulate_writes_and_refuses_rows_not_the_job(local_ray, photos, tmp_path, campro_command):
    good = tmp_path / "good"
    shutil.copytree(photos, good, ignore=shutil.ignore_patterns("bad"))
    simulate = tmp_path / "simulate"
    subprocess.run([campro_command, "simulate", PRESET, str(good), "-o", str(simulate), "--record"], check=True, capture_output=True)
    dst = tmp_path / "ray"
    s = campro.ray.protect(str(photos), str(dst), PRESET, concurrency=2)
    assert (s["done"], s["skipped"], s["refused"], s["failed"]) == (N, 0, 1, 3), s
    assert {pathlib.Path(r["path"]).name for r in s["rows"] if r["status"] == "error"} == {"truncated.jpg", "noise.png", "empty.jpg"}
    assert [pathlib.Path(r["path"]).name for r in s["rows"] if r["status"] == "refused"] == ["grey.png"]
    assert outputs(dst) == outputs(simulate)
    for rel in outputs(simulate):
        assert (dst / rel).read_bytes() == (simulate / rel).read_bytes(), rel
    assert verify_all(dst) == N


def test_a_second_run_writes_nothing_and_reports_everything_skipped(local_ray, photos, tmp_path):
    dst = tmp_path / "out"
    campro.ray.protect(str(photos), str(dst), PRESET, concurrency=2)
    before = {p: p.stat().st_mtime_ns for p in dst.rglob("*")}
    s = campro.ray.protect(str(photos), str(dst), PRESET, concurrency=2)
    assert (s["done"], s["skipped"], s["refused"], s["failed"]) == (0, N, 1, 3), s
    assert {p: p.stat().st_mtime_ns for p in dst.rglob("*")} == before


class DiesOnce(campro.ray.ProtectFiles):
    """A worker that kills its own process in the middle of its first batch (once per job)."""

    def __call__(self, batch):
        marker = self.dst.parent / "died"
        if not marker.exists():
            half = {k: v[: len(v) // 2] for k, v in batch.items()}
            super().__call__(half)  # half the batch written, then the process dies
            marker.write_text("once")
            os.kill(os.getpid(), signal.SIGKILL)
        return super().__call__(batch)


def test_a_worker_that_dies_mid_batch_is_retried_and_every_output_exists_once(local_ray, photos, tmp_path):
    dst = tmp_path / "out"
    rows = campro.ray.read_photos(str(photos)).map_batches(
        DiesOnce,
        fn_constructor_args=(PRESET, str(photos), str(dst)),
        concurrency=2,
        batch_size=8,
        batch_format="numpy",
        max_restarts=-1,
        max_task_retries=3,
    ).take_all()
    assert (tmp_path / "died").exists(), "the worker never died: the test tests nothing"
    by_path = {}
    for r in rows:
        by_path.setdefault(r["path"], []).append(r["campro_status"])
    assert len(by_path) == N + 4 and all(len(v) == 1 for v in by_path.values())
    assert sum(v == ["ok"] or v == ["skipped"] for v in by_path.values()) == N
    # Each written row carries its output's record, the file beside it.
    for r in rows:
        if r["campro_status"] in ("ok", "skipped"):
            assert json.loads(r["campro_record"]) == json.loads(pathlib.Path(r["output"] + ".campro.json").read_text())
    assert verify_all(dst) == N
    assert not [p for p in dst.rglob("*") if p.name.startswith(".campro")], "no half-written file is left"


def test_a_job_stopped_halfway_then_rerun_completes_with_nothing_lost(photos, tmp_path):
    dst = tmp_path / "out"
    cmd = [sys.executable, "-m", "campro.ray", "protect", str(photos), str(dst), "--preset", PRESET, "--concurrency", "1", "--batch-size", "4"]
    job = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(dst.rglob("*.campro.json"))) < N // 4:
        time.sleep(0.2)
    os.killpg(job.pid, signal.SIGKILL)  # the driver and its workers, mid-job
    job.wait()
    halfway = len(list(dst.rglob("*.campro.json")))
    assert 0 < halfway < N, halfway
    r = subprocess.run(cmd, capture_output=True, text=True)
    out = r.stdout
    assert r.returncode == 1 and "refused 1, failed 3" in out, (r.returncode, out, r.stderr[-2000:])  # the corrupt files
    # What had its record is skipped (the killed driver's workers may finish a batch or two
    # before Ray reaps them: at least what was there); the rest is done now, a photo killed
    # between its output and its record included (its bytes are checked and kept).
    done, skipped = map(int, re.search(r"done (\d+), skipped (\d+) ", out).groups())
    assert done + skipped == N and skipped >= halfway and done > 0, out
    assert verify_all(dst) == N


def test_the_docs_five_line_example_runs_as_written(local_ray, photos, tmp_path):
    doc = (pathlib.Path(__file__).resolve().parents[3] / "docs" / "datasets.md").read_text()
    block = re.search(r"```python\n(.*?)```", doc, re.S).group(1)
    assert len(block.strip().splitlines()) <= 6, block
    (tmp_path / "photos").mkdir()
    for p in sorted((photos / "a").glob("*.jpg"))[:5]:
        shutil.copyfile(p, tmp_path / "photos" / p.name)
    shutil.copyfile(photos / "bad" / "grey.png", tmp_path / "photos" / "grey.png")
    exec(compile(block.replace("/data/", f"{tmp_path}/"), "docs/datasets.md", "exec"), {})
    written = ray.data.read_parquet(str(tmp_path / "protected")).take_all()
    assert len(written) == 5 and all(r["campro_status"] == "ok" for r in written)
    cam = campro.Camera(PRESET)
    for r in written:
        assert r["image"].shape[2] == 3 and r["campro_preset_sha256"] == cam._native.preset_sha256
