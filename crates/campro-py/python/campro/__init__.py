"""campro: a camera that defeats face recognition while people are still detected.

CamPro (NDSS 2024) tunes the two stages every camera's image signal processor already has,
a 3x3 colour correction matrix and a tone curve, so that what the camera outputs hides
faces from face recognition. This package is the same Rust code as the ``campro`` command
(which it also installs):

    import campro
    cam = campro.Camera("campro-omega-0.5")          # a bundled preset, a file, or JSON
    photo = campro.read("photo.jpg")                  # H x W x 3 uint8 (or uint16), upright
    campro.write("out.jpg", cam.capture(photo), like="photo.jpg")   # what `simulate` writes

Images are numpy arrays of RGB samples, H x W x 3, C order: uint8 (codes 0..255) or
uint16 (0..65535). Every call returns new arrays and never changes its input. The camera
releases the GIL while it works, so threads run in parallel, and it pickles, so it can be
sent to worker processes (``campro.ray`` protects datasets on Ray Data).
"""

from __future__ import annotations

import json as _json
import os
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

from . import _campro
from ._campro import Error

__all__ = ["Camera", "Error", "presets", "read", "write", "__version__"]
__version__ = "0.1.0"

PathLike = Union[str, "os.PathLike[str]"]


def presets() -> List[Dict[str, Any]]:
    """The bundled presets, as ``campro presets`` lists them.

    Each is a dict: ``name``; ``pick`` (what to pick it for, in words); ``enhancer`` (it
    ships an image enhancer for people, see :meth:`Camera.enhance`); ``rated_for_grey``
    (grey pictures are protected; otherwise they are refused); ``protective`` (its worst
    measured face-recognition top-1 is at most 15%: the rest are for comparisons, and a
    phone never calls them Protected); ``description`` (its
    measured privacy and utility).
    """
    return [dict(p) for p in _campro.presets()]


def _rebuild(spec: str, allow_grey: bool) -> "Camera":
    return Camera(spec, allow_grey=allow_grey)


class Camera:
    """A camera with one CamPro parameter set.

    ``preset`` is a bundled preset's name (:func:`presets`), the path of a parameter file,
    or a parameter file's JSON text. ``allow_grey=True`` captures grey or near-grey
    pictures (black-and-white, infrared) instead of refusing them: the preset does not
    protect those, as ``campro simulate --allow-grey``.

    Raises :class:`Error` when the preset cannot be read (one line naming the field and
    the rule).
    """

    __slots__ = ("_native",)

    def __init__(self, preset: Union[str, "os.PathLike[str]"], *, allow_grey: bool = False) -> None:
        if isinstance(preset, os.PathLike):
            preset = os.fspath(preset)
        if not isinstance(preset, str):
            raise TypeError(f"preset must be a name, a path or JSON text, got {type(preset).__name__}")
        self._native = _campro.Camera(preset, allow_grey)

    @property
    def name(self) -> str:
        """The parameter set's name."""
        return self._native.name

    @property
    def json(self) -> str:
        """The parameter set as parameter-file JSON."""
        return self._native.json

    @property
    def allow_grey(self) -> bool:
        """Whether grey pictures are captured (unprotected) instead of refused."""
        return self._native.allow_grey

    def __repr__(self) -> str:
        return f"campro.Camera({self.name!r}, allow_grey={self.allow_grey})"

    def __reduce__(self):
        return (_rebuild, (self._native.spec, self.allow_grey))

    def capture(
        self, image: Union[np.ndarray, Sequence[np.ndarray]], *, bit_depth: int = 8
    ) -> Union[np.ndarray, List[np.ndarray]]:
        """What the camera outputs for ``image``: bit for bit what ``campro simulate`` writes.

        ``image``: an H x W x 3 RGB array (uint8, or uint16 for 16-bit photos); a batch,
        N x H x W x 3, which gives an N x H x W x 3 array; or a list of arrays of any sizes,
        which gives a list. ``bit_depth``: the output's, 8 (uint8, the default) or 16
        (uint16, ``--bit-depth 16``). The pictures of a batch or list run in parallel on
        every core, the GIL released.

        Raises ``ValueError`` for a wrong dtype or shape, :class:`Error` for a grey picture
        (refused unless ``allow_grey``), naming its index in a batch.
        """
        if isinstance(image, np.ndarray):
            if image.ndim == 4:
                if image.shape[0] == 0:
                    raise ValueError("expected at least one image in the batch, got shape (0, ...)")
                batch = np.ascontiguousarray(image)
                if batch.dtype == np.uint8 and bit_depth == 8:
                    return self._native.capture_batch(batch)
                return np.stack(self._capture_all(list(batch), bit_depth))
            (out,) = self._capture_all([_contiguous(image)], bit_depth)
            return out
        if isinstance(image, (list, tuple)):
            return self._capture_all([_contiguous(a) for a in image], bit_depth)
        raise ValueError(f"expected a numpy array or a list of them, got {type(image).__name__}")

    def _capture_all(self, images: List[Any], bit_depth: int) -> List[np.ndarray]:
        """Every image captured, or the first failure raised (naming its index in a list)."""
        if bit_depth not in (8, 16):
            raise ValueError(f"bit_depth must be 8 or 16, got {bit_depth}")
        results = self._native.capture_each(images, bit_depth)
        for i, (_, failure) in enumerate(results):
            if failure is not None:
                kind, line = failure
                where = f"image {i}: " if len(images) > 1 else ""
                raise (ValueError if kind == "invalid" else Error)(where + line)
        return [out for out, _ in results]

    def enhance(self, captured: np.ndarray, *, models: Optional[PathLike] = None) -> np.ndarray:
        """What the preset's image enhancer shows a person, from a captured uint8 image.

        Every face its face guard finds is pixelated, whatever the network does (the
        guard's detector: the models ``campro models fetch`` installs, or those in
        ``models``). Raises :class:`Error` when the preset ships no enhancer, when it was
        given as JSON text, or when the guard's detector is missing: nothing is enhanced
        without it.
        """
        return self._native.enhance(_contiguous(captured), None if models is None else os.fspath(models))

    def camera2(self, capture_result: Union[None, str, Dict[str, Any], PathLike] = None) -> Dict[str, Any]:
        """The Camera2 values that make a phone this camera, as ``campro convert PRESET
        --target camera2 --format json`` prints them.

        ``capture_result``: one of the phone's auto-mode ``CaptureResult``s (its own colour
        transform and gains, which the values are composed with), as a dict, JSON text or
        the path of a saved one (docs/commands.md); without it, a device whose own transform
        is the identity.
        """
        text: Optional[str]
        if capture_result is None:
            text = None
        elif isinstance(capture_result, dict):
            text = _json.dumps(capture_result)
        elif isinstance(capture_result, str) and capture_result.lstrip().startswith("{"):
            text = capture_result
        else:
            path = os.fspath(capture_result)
            with open(path, "rb") as f:
                raw = f.read((1 << 20) + 1)
            if len(raw) > 1 << 20:
                raise Error(f"{path}: a capture result is at most 1 MiB")
            text = raw.decode("utf-8")
        return _json.loads(self._native.camera2_json(text))


def _contiguous(a: Any) -> Any:
    """``a`` in C order (a copy only when it is not), so that strided views work too."""
    if isinstance(a, np.ndarray) and not a.flags.c_contiguous:
        return np.ascontiguousarray(a)
    return a


def read(path: PathLike) -> np.ndarray:
    """The photo at ``path`` (PNG, JPEG, TIFF, WebP, HEIC) as ``campro simulate`` reads it:
    upright (its EXIF orientation applied), H x W x 3 RGB, uint8, or uint16 for 16-bit
    files. Files are read with the command's size cap and memory budget.
    """
    return _campro.read(os.fspath(path))


def write(
    path: PathLike,
    image: np.ndarray,
    *,
    like: Optional[PathLike] = None,
    metadata: str = "keep-safe",
    quality: int = 92,
    force: bool = False,
) -> None:
    """Writes ``image`` (H x W x 3, uint8 or uint16) to ``path`` as ``campro simulate`` does.

    The format is the extension's (.png, .jpg/.jpeg, .tif/.tiff, .webp; 16 bits to PNG and
    TIFF only); JPEG at ``quality`` (1..100; 92 as ``simulate``). ``like``: the input photo, whose metadata the
    output keeps under ``metadata``: ``"keep-safe"`` (date, camera, exposure, colour
    profile; never GPS, names, serials or thumbnails), ``"keep"`` (every main-image field,
    GPS too, never a thumbnail or maker note) or ``"strip"`` (nothing). The file is written
    whole or not at all; an existing one is replaced only with ``force``, and never the
    ``like`` photo itself.
    """
    _campro.write(
        os.fspath(path),
        _contiguous(image),
        None if like is None else os.fspath(like),
        metadata,
        quality,
        force,
    )
