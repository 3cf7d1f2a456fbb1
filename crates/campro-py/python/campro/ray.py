"""campro on Ray Data: protect a dataset on every core of every node, losing nothing.

Two ways in (docs/datasets.md):

- :class:`Protect`, a callable class for ``ds.map_batches`` over numpy image batches, in an
  actor pool::

      import ray, campro.ray
      ds = ray.data.read_images("s3://bucket/frames/", include_paths=True)
      ds = ds.map_batches(campro.ray.Protect, fn_constructor_kwargs={"preset": "campro-omega-0.5"},
                          concurrency=4, batch_format="numpy")
      ds.filter(lambda r: r["campro_status"] == "ok").write_parquet("s3://bucket/protected/")

- the command, for a folder of photos whose outputs must be what ``campro simulate`` writes
  (names, formats, metadata, records)::

      python -m campro.ray protect SRC DST --preset campro-omega-0.5 [--address auto] [--enhance]

Each picture is a pure function of its pixels and the preset, so a worker loads the preset
once and a failure is one row: a bad picture becomes a row with its error and never fails
the batch or the job.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time
from typing import Any, Dict, List, Optional

import numpy as np

import campro

__all__ = ["Protect", "ProtectFiles", "read_photos", "protect", "main"]

# What `simulate` reads (HEIC through the system's libheif): campro's own decoder reads the
# bytes, so that the outputs are simulate's, byte for byte.
IMAGE_EXTENSIONS = ["png", "jpg", "jpeg", "tif", "tiff", "webp", "heic", "heif", "PNG", "JPG", "JPEG", "TIF", "TIFF", "WEBP", "HEIC", "HEIF"]


def _ray():
    try:
        import ray  # noqa: F401
        import ray.data  # noqa: F401
    except ImportError as e:  # pragma: no cover - the message is the test
        raise campro.Error(f"campro.ray needs Ray Data: pip install 'campro[ray]' ({e})") from None
    return sys.modules["ray"]


def _column(values: List[Any], dtype=None) -> np.ndarray:
    """A column of one value a row (strings as an object array: Ray keeps them as strings)."""
    out = np.empty(len(values), dtype=object if dtype is None else dtype)
    out[:] = values
    return out


class Protect:
    """The camera as a Ray Data transform over numpy image batches.

    ``ds.map_batches(Protect, fn_constructor_kwargs={"preset": ...}, concurrency=N,
    batch_format="numpy")``: each actor loads the preset once. A batch's ``column``
    (default ``"image"``) holds H x W x 3 uint8 (or uint16) RGB images, one array of
    N x H x W x 3 or an object array of images of different sizes (read-only views are
    fine). Returned: the batch with the column replaced by the protected images (a failed
    row holds an empty 0 x 0 x 3 array) and these columns added:

    - ``campro_status``: ``"ok"``, ``"refused"`` (a grey picture, which the preset does not
      protect) or ``"error"``;
    - ``campro_error``: the one-line reason, ``""`` when ok;
    - ``campro_preset_sha256``: SHA-256 of the parameter file, as records name it.

    ``enhance=True`` also runs the preset's enhancer behind its face guard (its detector
    from ``models``, else ``campro models fetch``'s folder).
    """

    def __init__(
        self,
        preset: str,
        *,
        enhance: bool = False,
        allow_grey: bool = False,
        column: str = "image",
        bit_depth: int = 8,
        models: Optional[str] = None,
    ) -> None:
        self.camera = campro.Camera(preset, allow_grey=allow_grey)
        self.enhance = enhance
        self.column = column
        self.bit_depth = bit_depth
        self.models = models

    def __call__(self, batch: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
        if self.column not in batch:
            raise campro.Error(f"the batch has no column {self.column!r} (its columns: {sorted(batch)}); pass column=")
        images = list(batch[self.column])
        results = self.camera._native.capture_each(images, self.bit_depth)
        outs, status, errors = [], [], []
        for out, err in results:
            if out is not None and self.enhance:
                try:
                    out = self.camera.enhance(out, models=self.models)
                except (campro.Error, ValueError) as e:
                    out, err = None, ("error", str(e))
            if out is None:
                kind, line = err
                kind = "refused" if kind == "refused" else "error"
                outs.append(np.zeros((0, 0, 3), np.uint8 if self.bit_depth == 8 else np.uint16))
                status.append(kind)
                errors.append(line)
            else:
                outs.append(out)
                status.append("ok")
                errors.append("")
        batch = dict(batch)
        same = len({o.shape for o in outs}) == 1 and all(s == "ok" for s in status)
        batch[self.column] = np.stack(outs) if same and outs else _column(outs)
        batch["campro_status"] = _column(status)
        batch["campro_error"] = _column(errors)
        batch["campro_preset_sha256"] = _column([self.camera._native.preset_sha256] * len(outs))
        return batch


class ProtectFiles:
    """The command's transform: photo files' bytes in, ``simulate``'s files out.

    Takes batches of ``ray.data.read_binary_files(SRC, include_paths=True)`` (columns
    ``bytes`` and ``path``); writes each output under ``dst`` at the input's path relative to
    ``src``, named and encoded as ``campro simulate`` names and encodes it, with its record
    beside it, atomically. An output whose record verifies (this preset, this input, this
    output) is skipped, so a retried batch or a rerun job redoes nothing. The photos of a
    batch run in parallel on every core of the node. Returns one row a photo: ``path``,
    ``output``, ``campro_status`` (``ok``, ``skipped``, ``refused``, ``error``),
    ``campro_error``, ``campro_record`` (the record's JSON text beside the output, ``""``
    without one) and ``seconds`` (the batch's wall time a photo).
    """

    def __init__(
        self,
        preset: str,
        src: str,
        dst: str,
        *,
        enhance: bool = False,
        allow_grey: bool = False,
        metadata: str = "keep-safe",
        quality: int = 92,
        bit_depth: int = 8,
        image_format: Optional[str] = None,
        models: Optional[str] = None,
        force: bool = False,
    ) -> None:
        self.camera = campro.Camera(preset, allow_grey=allow_grey)
        self.src = src.rstrip("/")
        self.dst = pathlib.Path(dst)
        self.opts = dict(
            bit_depth=bit_depth, quality=quality, metadata=metadata, enhance=enhance, models=models, record=True
        )
        self.image_format = image_format
        self.force = force

    def relative(self, path: str) -> str:
        """The input's path below SRC (Ray gives the bucket or folder path it read)."""
        src = self.src.split("://", 1)[-1]
        p = path.split("://", 1)[-1]
        rel = os.path.relpath(p, src) if os.path.isabs(p) == os.path.isabs(src) else os.path.basename(p)
        if rel.startswith(".."):
            rel = os.path.basename(p)
        return rel

    def __call__(self, batch: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
        started = time.perf_counter()
        paths = [str(p) for p in batch["path"]]
        outs = [
            str(self.dst / campro._campro.output_name(self.relative(p), self.opts["bit_depth"], self.image_format))
            for p in paths
        ]
        jobs = [(self.relative(p), bytes(d), o) for p, d, o in zip(paths, batch["bytes"], outs)]
        # The batch's photos in parallel on every core of this node, as `simulate` runs them.
        results = self.camera._native.protect_each(jobs, force=self.force, **self.opts)
        seconds = (time.perf_counter() - started) / max(1, len(jobs))
        records = [_record_text(o) if st in ("ok", "ok-grey", "skipped") else "" for (st, _), o in zip(results, outs)]
        return {
            "path": _column(paths),
            "output": _column(outs),
            "campro_status": _column(["ok" if s.startswith("ok") else s for s, _ in results]),
            "campro_error": _column([e or "" for _, e in results]),
            "campro_record": _column(records),
            "seconds": _column([seconds] * len(jobs), np.float64),
        }


def _record_text(output: str) -> str:
    """The record beside ``output`` (``NAME.EXT.campro.json``, at most 64 KiB), as text."""
    with open(output + ".campro.json", "rb") as f:
        return f.read(64 << 10).decode("utf-8")


def read_photos(src: str, readers: int = 2):
    """The photo files under ``src`` (a folder or a bucket path) as a Ray dataset of their
    bytes and paths (``read_binary_files``): campro decodes them itself, so that the
    outputs are ``simulate``'s. The read tasks reserve no CPU (reading is I/O, and an actor
    pool that holds every CPU would otherwise leave none to read with), so their number is
    capped at ``readers``: uncapped, Ray started a worker process per file (36 on two cores)
    and the job ran at 1.5 images a second."""
    ray = _ray()
    return ray.data.read_binary_files(
        src,
        include_paths=True,
        file_extensions=IMAGE_EXTENSIONS,
        ray_remote_args={"num_cpus": 0},
        concurrency=readers,
    )


def protect(
    src: str,
    dst: str,
    preset: str,
    *,
    concurrency: int = 2,
    batch_size: int = 8,
    retries: int = 3,
    **options: Any,
) -> Dict[str, Any]:
    """Protects every photo under ``src`` into ``dst`` on the Ray cluster this process is
    connected to (``ray.init`` first; a local one is started otherwise). ``options`` are
    :class:`ProtectFiles`'s. Returns the summary: counts of ``done``, ``skipped``,
    ``refused``, ``failed``, ``images_per_second``, ``seconds`` and the failed rows.
    """
    started = time.perf_counter()
    ds = read_photos(src, readers=max(2, concurrency)).map_batches(
        ProtectFiles,
        fn_constructor_args=(preset, src, dst),
        fn_constructor_kwargs=options,
        concurrency=concurrency,
        batch_size=batch_size,
        batch_format="numpy",
        # A worker that dies is replaced and its batch run again: its finished photos
        # verify and are skipped, so nothing is redone or written twice.
        max_restarts=-1,
        max_task_retries=retries,
    )
    counts = {"ok": 0, "skipped": 0, "refused": 0, "error": 0}
    failed = []
    for row in ds.select_columns(["path", "campro_status", "campro_error"]).iter_rows():
        counts[row["campro_status"]] = counts.get(row["campro_status"], 0) + 1
        if row["campro_status"] in ("refused", "error"):
            failed.append({"path": row["path"], "status": row["campro_status"], "error": row["campro_error"]})
    seconds = time.perf_counter() - started
    done = counts["ok"]
    return {
        "done": done,
        "skipped": counts["skipped"],
        "refused": counts["refused"],
        "failed": counts["error"],
        "seconds": seconds,
        "images_per_second": (done + counts["skipped"]) / seconds if seconds > 0 else 0.0,
        "rows": sorted(failed, key=lambda r: r["path"]),
    }


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m campro.ray",
        description="Protect a folder (or bucket) of photos on Ray Data: simulate's outputs and records, resumable.",
    )
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("protect", help="every photo under SRC into DST, as `campro simulate --record` writes them")
    p.add_argument("src", help="a folder, or a bucket path Ray reads (s3://, gs://, ...)")
    p.add_argument("dst", help="the output folder, on a file system every worker writes to (local or shared)")
    p.add_argument("--preset", required=True, help="a bundled preset's name, or a parameter file every worker can read")
    p.add_argument("--address", default=None, help="a Ray cluster to join (auto: the one this machine belongs to); default: a local one")
    p.add_argument("--concurrency", type=int, default=None, help="actors (default: the cluster's CPUs)")
    p.add_argument("--batch-size", type=int, default=8)
    p.add_argument("--enhance", action="store_true", help="also the preset's enhancer, behind its face guard")
    p.add_argument("--allow-grey", action="store_true", help="write grey photos (not protected) instead of refusing them")
    p.add_argument("--metadata", choices=["strip", "keep-safe", "keep"], default="keep-safe")
    p.add_argument("--quality", type=int, default=92, help="JPEG quality of JPEG outputs, 1 to 100")
    p.add_argument("--bit-depth", type=int, choices=[8, 16], default=8)
    p.add_argument("--image-format", choices=["png", "jpeg", "tiff", "webp"], default=None)
    p.add_argument("--models", default=None, help="the face guard's models folder (--enhance)")
    p.add_argument("--force", action="store_true", help="redo and replace every output, verified or not")
    a = ap.parse_args(argv)
    ray = _ray()
    if not 1 <= a.quality <= 100:
        ap.error(f"--quality must be 1..100, got {a.quality}")
    ray.init(address=a.address, include_dashboard=False, log_to_driver=False, configure_logging=False)
    concurrency = a.concurrency or max(1, int(ray.cluster_resources().get("CPU", 1)))
    try:
        campro.Camera(a.preset)  # a bad preset is one line here, not an error in every actor
    except campro.Error as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    s = protect(
        a.src,
        a.dst,
        a.preset,
        concurrency=concurrency,
        batch_size=a.batch_size,
        enhance=a.enhance,
        allow_grey=a.allow_grey,
        metadata=a.metadata,
        quality=a.quality,
        bit_depth=a.bit_depth,
        image_format=a.image_format,
        models=a.models,
        force=a.force,
    )
    for r in s["rows"]:
        print(f"{r['status']}: {r['path']}: {r['error']}", file=sys.stderr)
    print(
        f"done {s['done']}, skipped {s['skipped']} (already there, verified), refused {s['refused']}, failed {s['failed']}; "
        f"{s['images_per_second']:.1f} images a second over {s['seconds']:.1f} s with {concurrency} actors"
    )
    return 1 if s["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
