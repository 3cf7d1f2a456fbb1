"""The Python API against the command: one scenario per test, on the installed wheel."""

import json
import pathlib
import pickle
import re
import threading
import time

import numpy as np
import pytest

import campro
from conftest import REPO, run

PRESET = "campro-omega-0.5"


@pytest.fixture(scope="module")
def cam():
    return campro.Camera(PRESET)


def simulate(campro_command, inputs, out, *flags):
    run([campro_command, "simulate", PRESET, *map(str, inputs), "-o", str(out), *flags])


def test_the_wheel_is_what_is_imported():
    # Not the build tree: the installed package, with its native module beside it.
    assert "site-packages" in campro.__file__, campro.__file__
    assert campro.__version__ == "0.1.0"


def test_write_of_capture_is_byte_for_byte_what_simulate_writes(campro_command, coco, tmp_path):
    simulate(campro_command, coco, tmp_path / "cli")
    cam = campro.Camera(PRESET)
    for src in coco:
        mine = tmp_path / "py" / src.name
        mine.parent.mkdir(exist_ok=True)
        campro.write(mine, cam.capture(campro.read(src)), like=src)
        assert mine.read_bytes() == (tmp_path / "cli" / src.name).read_bytes(), src.name


def test_capture_equals_simulates_lossless_pixels(campro_command, coco, tmp_path):
    simulate(campro_command, coco[:4], tmp_path, "--image-format", "png")
    cam = campro.Camera(PRESET)
    for src in coco[:4]:
        expected = campro.read(tmp_path / (src.stem + ".png"))
        got = cam.capture(campro.read(src))
        assert got.dtype == np.uint8 and got.shape == expected.shape
        assert np.array_equal(got, expected), src.name


def test_sixteen_bit_photos_take_the_reference_path_as_simulate(campro_command, coco, tmp_path):
    # A 16-bit PNG made from a real photo (codes spread over 0..65535, low bits set).
    eight = campro.read(coco[0]).astype(np.uint16)
    sixteen = eight * 257 + (np.arange(eight.size, dtype=np.uint16).reshape(eight.shape) % 251)
    campro.write(tmp_path / "in16.png", sixteen)
    assert np.array_equal(campro.read(tmp_path / "in16.png"), sixteen)
    for depth, flag in [(8, "8"), (16, "16")]:
        out = tmp_path / f"out{depth}"
        simulate(campro_command, [tmp_path / "in16.png"], out, "--bit-depth", flag)
        got = campro.Camera(PRESET).capture(sixteen, bit_depth=depth)
        assert got.dtype == (np.uint8 if depth == 8 else np.uint16)
        assert np.array_equal(got, campro.read(out / "in16.png")), depth


def test_a_batch_equals_single_calls(cam, coco):
    first = campro.read(coco[0])
    h, w, _ = first.shape
    same = [campro.read(p) for p in coco if campro.read(p).shape == first.shape][:3]
    batch = np.stack(same or [first])
    out = cam.capture(batch)
    assert out.shape == batch.shape and out.dtype == np.uint8
    for i, one in enumerate(batch):
        assert np.array_equal(out[i], cam.capture(one))
    # A strided batch (every other row) and a 16-bit one take the general path: the same.
    assert np.array_equal(cam.capture(batch[:, ::2]), np.stack([cam.capture(b[::2]) for b in batch]))
    wide = batch.astype(np.uint16) * 257
    assert np.array_equal(cam.capture(wide), np.stack([cam.capture(b) for b in wide]))


def test_a_list_of_different_sizes_gives_a_list(cam, coco):
    images = [campro.read(p) for p in coco[:5]]
    images.append(images[0][:17, :31])  # odd sizes, and a strided view
    out = cam.capture(images)
    assert isinstance(out, list) and len(out) == len(images)
    for a, b in zip(images, out):
        assert b.shape == a.shape
        assert np.array_equal(b, cam.capture(np.ascontiguousarray(a)))


def test_the_input_is_never_changed(cam, coco):
    image = campro.read(coco[1])
    before = image.copy()
    out = cam.capture(image)
    assert np.array_equal(image, before)
    assert not np.shares_memory(out, image)


def test_read_only_and_strided_arrays_give_the_correct_result(cam, coco):
    image = campro.read(coco[2])
    expected = cam.capture(image)
    frozen = image.copy()
    frozen.flags.writeable = False
    assert np.array_equal(cam.capture(frozen), expected)
    # A strided view (every other column) and a Fortran-ordered copy.
    assert np.array_equal(cam.capture(image[:, ::2]), expected[:, ::2])
    assert np.array_equal(cam.capture(np.asfortranarray(image)), expected)


@pytest.mark.parametrize(
    "bad, words",
    [
        (np.zeros((8, 8, 3), np.float32), "uint8"),
        (np.zeros((8, 8, 3), np.int16), "uint8"),
        (np.zeros((8, 8), np.uint8), "H x W x 3"),
        (np.zeros((8, 8, 4), np.uint8), "H x W x 3"),
        (np.zeros((0, 8, 3), np.uint8), "H x W x 3"),
        (np.zeros((0, 8, 8, 3), np.uint8), "at least one image"),
        ("photo.jpg", "numpy array"),
    ],
)
def test_a_wrong_dtype_or_shape_is_a_value_error(cam, bad, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        cam.capture(bad)


def test_bit_depth_is_8_or_16(cam):
    with pytest.raises(ValueError, match="bit_depth must be 8 or 16"):
        cam.capture(np.zeros((4, 4, 3), np.uint8), bit_depth=12)


def test_a_grey_picture_is_refused_unless_allowed(coco):
    grey = campro.read(coco[3]).mean(axis=2, keepdims=True).astype(np.uint8).repeat(3, axis=2)
    with pytest.raises(campro.Error, match="grey"):
        campro.Camera(PRESET).capture(grey)
    with pytest.raises(campro.Error, match="^image 1: .*grey"):
        campro.Camera(PRESET).capture([campro.read(coco[3]), grey])
    with pytest.raises(campro.Error, match="^image 1: .*grey"):
        campro.Camera(PRESET).capture(np.stack([campro.read(coco[3]), grey]))
    out = campro.Camera(PRESET, allow_grey=True).capture(grey)
    assert out.shape == grey.shape


def test_errors_are_campro_errors_with_the_commands_line():
    with pytest.raises(campro.Error, match="did you mean campro-omega-0.5"):
        campro.Camera("campro-omega0.5")
    with pytest.raises(campro.Error, match="the parameter JSON"):
        campro.Camera('{"format": "campro-params"}')
    assert issubclass(campro.Error, Exception)


def test_a_file_json_and_name_give_the_same_camera(coco):
    path = REPO / "params" / f"{PRESET}.json"
    image = campro.read(coco[4])
    by_name = campro.Camera(PRESET).capture(image)
    assert np.array_equal(campro.Camera(path).capture(image), by_name)
    assert np.array_equal(campro.Camera(path.read_text()).capture(image), by_name)


def test_pickle_round_trips_and_the_copy_gives_the_same_output(cam, coco, tmp_path):
    image = campro.read(coco[5])
    for original in [cam, campro.Camera(REPO / "params" / "identity.json", allow_grey=True)]:
        copy = pickle.loads(pickle.dumps(original))
        assert copy.name == original.name and copy.allow_grey == original.allow_grey
        assert np.array_equal(copy.capture(image), original.capture(image))


def test_two_threads_overlap_the_gil_is_released(cam):
    # While one thread is inside the native call, the other runs Python: it could not if
    # the call held the GIL (a C call is never preempted by the interpreter's switch).
    big = np.random.default_rng(1).integers(0, 256, (3000, 4000, 3), dtype=np.uint8)
    spans, ticks = [], []

    def worker():
        for _ in range(3):
            t0 = time.perf_counter()
            cam.capture(big)
            spans.append((t0, time.perf_counter()))

    t = threading.Thread(target=worker)
    t.start()
    while t.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    t.join()
    inside = sum(1 for x in ticks for a, b in spans if a < x < b)
    assert inside > 0, f"no Python ran during {len(spans)} native calls"
    # And two threads calling at once both finish with the right result.
    outs = [None, None]

    def one(i):
        outs[i] = cam.capture(big)

    threads = [threading.Thread(target=one, args=(i,)) for i in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert np.array_equal(outs[0], outs[1])


def test_presets_lists_what_the_command_lists(campro_command):
    listed = json.loads(run([campro_command, "presets", "--format", "json"]))
    mine = campro.presets()
    assert [p["name"] for p in mine] == [p["name"] for p in listed]
    for a, b in zip(mine, listed):
        assert (a["enhancer"], a["rated_for_grey"], a["protective"], a["description"]) == (
            b["enhancer"],
            b["ratedForGrey"],
            b["protective"],
            b["description"],
        )
    assert {p["name"] for p in mine if p["protective"]} == {
        "campro-omega-0.5",
        "campro-omega-0.5-distill",
        "campro-omega-0.5-hour",
        "campro-omega-1-shared-continued",
    }


def test_camera2_values_are_the_converters(campro_command, cam, tmp_path):
    assert cam.camera2() == json.loads(run([campro_command, "convert", PRESET, "--target", "camera2", "--format", "json"]))
    result = {
        "android.colorCorrection.transform": [[0.9, 0.1, 0.0], [0.05, 1.0, -0.05], [0.0, 0.1, 0.9]],
        "android.colorCorrection.gains": [2.0, 1.0, 1.0, 1.6],
    }
    saved = tmp_path / "result.json"
    saved.write_text(json.dumps(result))
    cli = json.loads(
        run([campro_command, "convert", PRESET, "--target", "camera2", "--format", "json", "--capture-result", str(saved)])
    )
    assert cam.camera2(result) == cli
    assert cam.camera2(saved) == cli


def test_write_refuses_to_replace_without_force_and_never_its_input(cam, coco, tmp_path):
    out = tmp_path / "a.png"
    image = campro.read(coco[0])
    campro.write(out, image)
    with pytest.raises(campro.Error, match="exists"):
        campro.write(out, image)
    campro.write(out, image, force=True)
    with pytest.raises(campro.Error, match="input"):
        campro.write(out, image, like=out, force=True)
    with pytest.raises(ValueError, match="metadata"):
        campro.write(tmp_path / "b.png", image, metadata="all")
    with pytest.raises(campro.Error, match="extension"):
        campro.write(tmp_path / "b.gif", image)


def test_enhance_without_the_guards_detector_enhances_nothing(tmp_path, coco):
    # An empty models folder: the face guard cannot load, so nothing is enhanced.
    captured = campro.Camera(PRESET).capture(campro.read(coco[0]))
    with pytest.raises(campro.Error, match="nothing is enhanced without it"):
        campro.Camera(PRESET).enhance(captured, models=tmp_path)
    with pytest.raises(campro.Error, match="no enhancer"):
        campro.Camera("campro-omega-1").enhance(captured, models=tmp_path)


def test_the_console_script_is_the_command(campro_command):
    assert "campro" in run([campro_command, "--version"])
    assert PRESET in run([campro_command, "presets"])


def test_the_readmes_python_block_runs_as_written(coco, tmp_path, monkeypatch):
    readme = (REPO / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", readme, re.S)
    assert blocks, "the README has a Python block"
    (tmp_path / "photos").mkdir()
    for p in coco[:3]:
        (tmp_path / "photos" / p.name).write_bytes(p.read_bytes())
    (tmp_path / "photo.jpg").write_bytes(coco[0].read_bytes())
    monkeypatch.chdir(tmp_path)
    exec(compile(blocks[0], "README.md", "exec"), {})
