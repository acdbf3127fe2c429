"""A dataset for trainers that assume each image's principal point at its centre: the
reference 3D Gaussian splatting code (graphdeco-inria) and those that read COLMAP's model
as it does.

Why a dataset of its own: ``calibration/colmap_points`` gives every view its principal
point, up to 20.5 px from the image centre on the default data (the subaperture views'
shift, registration B's ``pp``), and names the images ``<shot>/<r>_<c>.png``. The
reference code builds each camera's frustum from the focal length alone, symmetric about
the image centre, and names images by their base name, which folds the 700 views of the
default data into 25 names: it cannot train on that model as it is.

Here each view is cropped to the largest window centred on its principal point
(:func:`centred_window`, per axis), the fractional part of the crop's origin taken by a
Lanczos-3 kernel (:func:`lanczos_taps`; an integer origin copies the pixels as they are),
so that the new image's centre is the principal point exactly. Its camera is PINHOLE with
``cx = W' / 2``, ``cy = H' / 2`` (COLMAP's convention: the centre of pixel (0, 0) at
(0.5, 0.5)), the same focal length and pose; the image is named ``<shot>_<r>_<c>.png``
(8-bit RGB: :func:`eight_bit`), and its 2-D observations move with the crop. The 3-D
points are the model's. Layout, as the reference code and COLMAP's undistorter write it::

    gaussian_splatting/images/<shot>_<r>_<c>.png
    gaussian_splatting/sparse/0/{cameras,images,points3D}.bin (+ rigs.bin, frames.bin)
    gaussian_splatting/crops.json  (each view's crop in its source view's pixels)

``pycolmap`` is imported inside the functions: a process must import cv2 first.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from plenocal.names import flat_key

#: the Lanczos kernel's half-width (taps per axis: 2 x this)
LANCZOS_A = 3
FORMAT = "plenocal.gaussian_splatting"


def centred_window(c: float, size: int) -> tuple[int, float, int]:
    """The largest window of an axis of ``size`` pixels whose centre is ``c`` (COLMAP's
    convention: pixel i covers [i, i + 1)), of an even number of pixels ``n``: its first
    pixel is the source's pixel ``origin = c - n / 2`` (pixel units, pixel centres at
    integers), returned as its integer part, fractional part and ``n``. Every pixel of the
    window then lies within the source, ``0 <= origin`` and ``origin + n - 1 <= size - 1``.

    >>> centred_window(312.5, 666)
    (0, 0.5, 624)
    """
    if not 0.0 < c < size:
        raise ValueError(f"principal point {c} px outside an image of {size} px")
    n = 2 * math.floor(min(c, size - c))
    if n < 2:
        raise ValueError(f"principal point {c} px within a pixel of the border of an image "
                         f"of {size} px: no centred window")
    origin = c - n / 2
    whole = math.floor(origin)
    return whole, origin - whole, n


def lanczos_taps(frac: float, a: int = LANCZOS_A) -> np.ndarray:
    """(2a,) float64 weights of the source pixels ``s = k - (a - 1)`` (k = 0 .. 2a - 1)
    about an integer pixel for the sample ``frac`` (0 <= frac < 1) past it: the Lanczos
    kernel ``sinc(t) sinc(t / a)`` at ``t = s - frac``, corrected by the least change that
    makes the weights sum to 1 and their first moment ``sum w s`` equal ``frac``. The
    plain normalised kernel moves a ramp, and every smooth feature, by up to 0.02 px (its
    first moment at frac 0.75: 0.7698); corrected, a constant and a linear ramp are
    sampled exactly. At ``frac = 0`` one tap is 1 and the others 0: the pixel itself."""
    if not 0.0 <= frac < 1.0:
        raise ValueError(f"fraction {frac} outside [0, 1)")
    if frac == 0.0:  # sinc's zeros, exactly (np.sinc leaves 1e-17 there)
        return np.eye(2 * a)[a - 1]
    s = np.arange(2 * a, dtype=np.float64) - (a - 1)
    w = np.sinc(s - frac) * np.sinc((s - frac) / a)
    A = np.stack([np.ones_like(s), s])
    return w + A.T @ np.linalg.solve(A @ A.T, np.array([1.0, frac]) - A @ w)


def shift_crop(image: np.ndarray, x: tuple[int, float, int], y: tuple[int, float, int]
               ) -> np.ndarray:
    """The window ``x``, ``y`` (each :func:`centred_window`'s triple) of ``image`` (h, w)
    or (h, w, C), uint8, uint16 or float32: pixel (i, j) of the result samples the source
    at (x origin + j, y origin + i), by :func:`lanczos_taps` along each axis (the border
    mirrored where a tap falls outside); integers rounded and clipped to their range."""
    import cv2  # noqa: PLC0415

    (x0, fx, w), (y0, fy, h) = x, y
    if x0 < 0 or y0 < 0 or x0 + w > image.shape[1] or y0 + h > image.shape[0]:
        raise ValueError(f"window {w}x{h} at ({x0}, {y0}) outside an image of "
                         f"{image.shape[1]}x{image.shape[0]}")
    if fx == 0.0 and fy == 0.0:
        return image[y0:y0 + h, x0:x0 + w].copy()
    src = image.astype(np.float32)
    out = cv2.sepFilter2D(src, cv2.CV_32F, lanczos_taps(fx).astype(np.float32),
                          lanczos_taps(fy).astype(np.float32),
                          anchor=(LANCZOS_A - 1, LANCZOS_A - 1),
                          borderType=cv2.BORDER_REFLECT_101)
    out = out[y0:y0 + h, x0:x0 + w]
    if out.ndim == 2 and image.ndim == 3:
        out = out[:, :, None]
    if image.dtype == np.float32:
        return np.ascontiguousarray(out)
    top = float(np.iinfo(image.dtype).max)
    return np.clip(np.rint(out), 0.0, top).astype(image.dtype)


def eight_bit(image: np.ndarray) -> np.ndarray:
    """``image`` as uint8: 16-bit samples scaled by 255 / 65535 and rounded (the trainers'
    image readers, Pillow among them, take 8-bit RGB PNGs; a 16-bit one is not read as
    RGB by every one)."""
    from plenocal.io.files import to_float, to_uint8  # noqa: PLC0415

    if image.dtype == np.uint8:
        return image
    if image.dtype != np.uint16:
        raise TypeError(f"views are uint8 or uint16, not {image.dtype}")
    return to_uint8(to_float(image))


def flat_name(name: str) -> str:
    """``<shot>/<r>_<c>.png`` -> ``<shot>_<r>_<c>.png`` (:func:`plenocal.names.flat_key`;
    unique: shot names hold no ``/``, and every view name is ``<r>_<c>``)."""
    return flat_key(name)


def export_gaussian_splatting(model_dir: str | Path, out_dir: str | Path,
                              read_view: Callable[[str], np.ndarray],
                              write_view: Callable[[Path, np.ndarray], None],
                              progress: Callable[[int, int], None] | None = None) -> dict:
    """Write the dataset of the module docstring into ``out_dir`` from the COLMAP model in
    ``model_dir`` (PINHOLE or SIMPLE_PINHOLE cameras; image names ``<shot>/<r>_<c>.png``)
    and the views ``read_view(key)`` gives (``key``: ``<shot>/<r>_<c>``). ``write_view``
    writes one image; ``progress(done, total)`` is called every 50 views. The folder is
    filled atomically. Returns crops.json's content."""
    import pycolmap  # noqa: PLC0415

    from plenocal.io.files import atomic_write_dir, write_json  # noqa: PLC0415

    rec = pycolmap.Reconstruction(str(model_dir))
    windows: dict[int, tuple[tuple[int, float, int], tuple[int, float, int]]] = {}
    sizes: dict[int, tuple[int, int]] = {}  # each camera's (width, height) in the model
    for cam_id, cam in rec.cameras.items():
        model = cam.model.name
        if model == "PINHOLE":
            fx, fy, cx, cy = (float(v) for v in cam.params)
        elif model == "SIMPLE_PINHOLE":
            fx, cx, cy = (float(v) for v in cam.params)
            fy = fx
        else:
            raise ValueError(f"{model_dir}: camera {cam_id} is {model}; a centred dataset "
                             "needs PINHOLE or SIMPLE_PINHOLE cameras (no distortion)")
        try:
            wx, wy = centred_window(cx, int(cam.width)), centred_window(cy, int(cam.height))
        except ValueError as exc:
            raise ValueError(f"{model_dir}: camera {cam_id}: {exc}") from None
        windows[cam_id] = (wx, wy)
        sizes[cam_id] = (int(cam.width), int(cam.height))
        cam.model = "PINHOLE"
        cam.width, cam.height = wx[2], wy[2]
        cam.params = [fx, fy, wx[2] / 2.0, wy[2] / 2.0]
    crops: dict[str, dict] = {}
    info: dict = {}
    names = {flat_name(im.name) for im in rec.images.values()}
    if len(names) != rec.num_images():
        raise ValueError(f"{model_dir}: image names that differ only by '/' and '_'")

    def write(tmp: Path) -> None:
        (tmp / "images").mkdir()
        (tmp / "sparse" / "0").mkdir(parents=True)
        order = sorted(rec.images, key=lambda i: rec.images[i].name)
        for done, image_id in enumerate(order, start=1):
            im = rec.images[image_id]
            key, _, _ = im.name.rpartition(".")
            wx, wy = windows[im.camera_id]
            view = read_view(key)
            if (view.shape[1], view.shape[0]) != sizes[im.camera_id]:
                raise ValueError(f"{model_dir}: view {key} is {view.shape[1]}x{view.shape[0]}"
                                 " px, its camera {}x{}: the views and the model are of two "
                                 "runs".format(*sizes[im.camera_id]))
            write_view(tmp / "images" / flat_name(im.name), eight_bit(shift_crop(view, wx, wy)))
            shift = np.array([wx[0] + wx[1], wy[0] + wy[1]])
            for point in im.points2D:
                point.xy = point.xy - shift
            crops[key] = {"image": flat_name(im.name),
                          "origin_px": [wx[0] + wx[1], wy[0] + wy[1]],
                          "size": [wx[2], wy[2]]}
            im.name = flat_name(im.name)
            if progress is not None and (done % 50 == 0 or done == len(order)):
                progress(done, len(order))
        rec.write_binary(str(tmp / "sparse" / "0"))
        info.update({"format": FORMAT, "version": 1,
                     "convention": "origin_px: the crop's first pixel in its source view "
                                   "(pixel centres at integers); each camera's principal "
                                   "point is its image's centre",
                     "views": dict(sorted(crops.items()))})
        write_json(tmp / "crops.json", info)

    atomic_write_dir(out_dir, write)
    return info
