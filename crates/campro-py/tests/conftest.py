"""Fixtures of the wheel's tests: they run against the installed wheel (.ci/run installs
it into a fresh venv), never the build tree, on real photos from ../shared."""

import os
import pathlib
import shutil
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


def shared_dir():
    """The project's shared data: $CAMPRO_SHARED, else ../shared beside the checkout."""
    given = os.environ.get("CAMPRO_SHARED")
    d = pathlib.Path(given) if given else REPO.parent / "shared"
    return d if d.is_dir() else None


def need_shared(rel):
    """The shared file or folder `rel`; skips without it, fails under CI=true."""
    d = shared_dir()
    path = d / rel if d else None
    if path is None or not path.exists():
        msg = f"../shared/{rel} is absent (the project's shared data)"
        if os.environ.get("CI") == "true":
            pytest.fail(msg + ": CI must have it")
        pytest.skip(msg)
    return path


def colour_photos(n):
    """The first `n` real COCO photos (JPEG, by name) in colour: COCO holds grey ones,
    which the presets refuse."""
    import campro

    images = need_shared("data/coco-person/images")
    cam = campro.Camera("campro-omega-0.5")
    found = []
    for p in sorted(p for p in images.iterdir() if p.suffix == ".jpg"):
        try:
            cam.capture(campro.read(p))
        except campro.Error:
            continue
        found.append(p)
        if len(found) == n:
            return found
    pytest.fail(f"fewer than {n} colour photos in {images}")


@pytest.fixture(scope="session")
def coco():
    """Twelve real COCO photos in colour."""
    return colour_photos(12)


@pytest.fixture(scope="session")
def campro_command():
    """The installed `campro` console script (the wheel's entry point)."""
    exe = shutil.which("campro")
    assert exe, "the wheel installs a `campro` command on PATH"
    return exe


def run(cmd, cwd=None):
    """Runs a command; its stdout, or a failure with its stderr."""
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    assert r.returncode == 0, f"{cmd} exited {r.returncode}: {r.stderr}"
    return r.stdout
