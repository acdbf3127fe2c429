"""What the MPEG tools need beside ``calibration/mpeg/cameras.json`` to rerun the
view-synthesis experiments: depth maps, textures and one RVS configuration per
experiment, so that a user with RVS runs an experiment with one command::

    cd results/<dataset>/calibration/mpeg && RVS rvs/exp1.json --noopengl

Layout (``<name>`` = ``<cam>_<view>``, the camera's name in ``cameras.json``):

- ``depth/<name>.yuv``: 16-bit LE YUV 4:2:0 normalised disparity over the camera's
  ``Depth_range`` (level 0 = invalid), ``depth/<name>.png`` the same levels as a
  16-bit grey PNG (:mod:`plenocal.export.depthmaps`);
- ``texture/<name>.yuv``: the view as 8-bit YUV 4:2:0 (the PNG is in ``views/``);
- ``rvs/exp<k>.json`` (Exp. 3: ``exp3_central.json``, ``exp3_lateral.json``): RVS
  configuration Version 3.0 whose outputs go to ``rvs/exp<k>_<target>.png``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from plenocal.export.depthmaps import write_depth16_png, write_depth16_yuv, write_texture_yuv
from plenocal.export.mpeg import mpeg_name
from plenocal.io.files import read_json, staged_outputs, to_float, to_uint8, write_json


def camera_ranges(mpeg_json: str | Path) -> dict[str, tuple[float, float, int, int]]:
    """Name -> (near, far, width, height) of every camera of an MPEG camera JSON."""
    doc = read_json(mpeg_json)
    return {c["Name"]: (float(c["Depth_range"][0]), float(c["Depth_range"][1]),
                        int(c["Resolution"][0]), int(c["Resolution"][1]))
            for c in doc["cameras"]}


def export_views(out_dir: str | Path, mpeg_json: str | Path, keys: Sequence[str],
                 depth: Callable[[str], np.ndarray], image: Callable[[str], np.ndarray],
                 experiments: Mapping[str, tuple[Sequence[str], Sequence[str]]],
                 blending_factor: float = 5.0) -> list[str]:
    """Write the depth maps and textures of ``keys`` (``<cam>/<view>``) and one RVS
    configuration per experiment ``name -> (inputs, targets)`` under ``out_dir`` (the
    folder of ``mpeg_json``), replacing its ``depth/``, ``texture/`` and ``rvs/`` whole,
    or, on an error, leaving them as they were; returns the files written, relative to
    ``out_dir``."""
    from plenocal.verify.rvs import rvs_config  # noqa: PLC0415

    out_dir = Path(out_dir)
    ranges = camera_ranges(mpeg_json)
    written = []
    have = set(keys)
    for exp, (inputs, _) in experiments.items():
        missing = [k for k in inputs if k not in have]
        if missing:
            raise ValueError(f"RVS configuration {exp}: no depth map exported for "
                             f"{', '.join(missing)}")
    # made in a folder of their own inside out_dir and moved into place once all are
    # written: a view that fails (its image missing, its depth map the wrong size) leaves
    # out_dir as it was, not with the views before it exported
    with staged_outputs(out_dir) as stage:
        for key in keys:
            name = mpeg_name(key)
            if name not in ranges:
                raise KeyError(f"{mpeg_json}: no camera {name} for the depth map of {key}")
            near, far, w, h = ranges[name]
            z = depth(key)
            if z.shape != (h, w):
                raise ValueError(f"depth map of {key} is {z.shape[1]}x{z.shape[0]}, camera "
                                 f"{name} in {mpeg_json} is {w}x{h}")
            write_depth16_yuv(stage / "depth" / f"{name}.yuv", z, near, far)
            write_depth16_png(stage / "depth" / f"{name}.png", z, near, far)
            img = to_uint8(to_float(image(key)))
            if img.ndim == 2:
                img = np.repeat(img[..., None], 3, axis=2)
            write_texture_yuv(stage / "texture" / f"{name}.yuv", img)
            written += [f"depth/{name}.yuv", f"depth/{name}.png", f"texture/{name}.yuv"]
        for exp, (inputs, targets) in experiments.items():
            names = [mpeg_name(k) for k in inputs]
            cfg = rvs_config(names, [mpeg_name(t) for t in targets],
                             [f"texture/{n}.yuv" for n in names],
                             [f"depth/{n}.yuv" for n in names],
                             [f"rvs/{exp}_{mpeg_name(t)}.png" for t in targets],
                             Path(mpeg_json).name, blending_factor)
            write_json(stage / "rvs" / f"{exp}.json", cfg)
            written.append(f"rvs/{exp}.json")
    return written
