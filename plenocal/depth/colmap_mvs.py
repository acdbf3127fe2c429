"""Depth by COLMAP's patch-match stereo (pycolmap), run in a subprocess.

The CUDA build of pycolmap (``pycolmap-cuda12``) aborts the whole process where no
GPU is visible, and the CPU wheel raises, so the work runs in a child process and
:func:`colmap_available` probes that child first. The workspace is COLMAP's dense
layout::

    <ws>/images/<name>.png           reference and sources
    <ws>/sparse/{cameras,images,points3D}.txt   PINHOLE cameras, known poses, no points
    <ws>/stereo/patch-match.cfg      reference, then its source images listed explicitly
    <ws>/stereo/{depth_maps,normal_maps,consistency_graphs}/

Depth bounds are given explicitly (no sparse points needed) and the minimum
triangulation angles are lowered for the small baselines of subaperture views.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.camera import PinholeCamera, k_to_colmap
from plenocal.config import stage_defaults
from plenocal.io.files import atomic_write_text, to_float, to_uint8, write_image, write_json


class DepthBackendError(RuntimeError):
    """A depth backend that cannot run here."""


COLMAP_HINT = ("install pycolmap-cuda12 and run on a GPU node, or use depth.backend: "
               "planesweep")


_COLMAP = stage_defaults("depth.colmap")


@dataclass(frozen=True)
class ColmapOptions:
    """COLMAP patch-match settings; defaults: ``depth.colmap`` of config.schema.yaml."""
    window_radius: int = _COLMAP["window_radius"]
    num_iterations: int = _COLMAP["num_iterations"]
    # COLMAP's own 1.0 is too large for subaperture baselines
    min_triangulation_angle_deg: float = _COLMAP["min_triangulation_angle_deg"]
    filter_min_triangulation_angle_deg: float = _COLMAP["filter_min_triangulation_angle_deg"]
    geom_consistency: bool = _COLMAP["geom_consistency"]  # needs the sources' depth maps too
    filter_min_ncc: float = _COLMAP["filter_min_ncc"]
    timeout_s: float = 1800.0


_PROBE = (
    "import sys, subprocess\n"
    "import pycolmap\n"
    "if not getattr(pycolmap, 'has_cuda', False):\n"
    "    print('pycolmap is built without CUDA'); sys.exit(3)\n"
    "try:\n"
    "    out = subprocess.run(['nvidia-smi', '-L'], capture_output=True, text=True, timeout=30)\n"
    "except (OSError, subprocess.TimeoutExpired):\n"
    "    print('nvidia-smi not found: no GPU visible'); sys.exit(4)\n"
    "if out.returncode != 0 or 'GPU' not in out.stdout:\n"
    "    print('no GPU visible'); sys.exit(4)\n"
    "print('ok')\n"
)


def colmap_available() -> tuple[bool, str]:
    """(can run, why not) - probed in a subprocess so that a CUDA wheel without a GPU
    cannot abort this process. Without ``nvidia-smi`` on the PATH the probe's answer is
    known (no GPU visible) and the subprocess, with its pycolmap import (half a second
    per depth job), is skipped."""
    if shutil.which("nvidia-smi") is None:
        return False, "nvidia-smi not found: no GPU visible"
    try:
        out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                             timeout=120)
    except subprocess.TimeoutExpired:
        return False, "probing pycolmap timed out"
    msg = (out.stdout.strip() or out.stderr.strip().splitlines()[-1:] or ["failed"])
    msg = msg if isinstance(msg, str) else msg[0]
    return out.returncode == 0, msg


def image_name(index: int) -> str:
    return f"view{index:03d}.png"


def prepare_workspace(ws: str | Path, ref: PinholeCamera, ref_img: np.ndarray,
                      srcs: list[PinholeCamera], src_imgs: list[np.ndarray]) -> list[str]:
    """Write the dense workspace; returns the image names (reference first)."""
    import cv2  # noqa: PLC0415,F401  (cv2 before anything that imports pycolmap)

    ws = Path(ws)
    cams = [ref, *srcs]
    imgs = [ref_img, *src_imgs]
    names = [image_name(i) for i in range(len(cams))]
    for name, img in zip(names, imgs, strict=True):
        im = np.asarray(img)
        write_image(ws / "images" / name, im if im.dtype in (np.uint8, np.uint16)
                    else to_uint8(to_float(im)))
    cam_lines = ["# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
    img_lines = ["# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME", "# POINTS2D[]"]
    for i, (c, name) in enumerate(zip(cams, names, strict=True), start=1):
        K = k_to_colmap(c.K)
        cam_lines.append(f"{i} PINHOLE {c.width} {c.height} "
                         + " ".join(_num(x) for x in (K[0, 0], K[1, 1], K[0, 2], K[1, 2])))
        M = c.world_to_cam
        q = _quat_wxyz(M[:3, :3])
        t = M[:3, 3]
        img_lines.append(f"{i} " + " ".join(_num(x) for x in (*q, *t)) + f" {i} {name}")
        img_lines.append("")
    atomic_write_text(ws / "sparse" / "cameras.txt", "\n".join(cam_lines) + "\n")
    atomic_write_text(ws / "sparse" / "images.txt", "\n".join(img_lines) + "\n")
    atomic_write_text(ws / "sparse" / "points3D.txt", "# no points: depth bounds are given\n")
    for sub in ("depth_maps", "normal_maps", "consistency_graphs"):
        (ws / "stereo" / sub).mkdir(parents=True, exist_ok=True)
    # patch-match.cfg: reference, then its sources listed explicitly
    cfg = f"{names[0]}\n{', '.join(names[1:])}\n"
    atomic_write_text(ws / "stereo" / "patch-match.cfg", cfg)
    atomic_write_text(ws / "stereo" / "fusion.cfg", f"{names[0]}\n")
    return names


def _num(x: float) -> str:
    return repr(float(x))


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    """Rotation matrix to a unit quaternion (w, x, y, z), w >= 0."""
    from scipy.spatial.transform import Rotation  # noqa: PLC0415

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return q if q[0] >= 0 else -q


def patch_match_options(near: float, far: float, size: int, opt: ColmapOptions) -> dict:
    """The PatchMatchOptions fields set for this run."""
    return {
        "max_image_size": int(size),
        "window_radius": int(opt.window_radius),
        "num_iterations": int(opt.num_iterations),
        "depth_min": float(near),
        "depth_max": float(far),
        "min_triangulation_angle": float(opt.min_triangulation_angle_deg),
        "filter_min_triangulation_angle": float(opt.filter_min_triangulation_angle_deg),
        "filter_min_ncc": float(opt.filter_min_ncc),
        "geom_consistency": bool(opt.geom_consistency),
        "filter": True,
        "filter_min_num_consistent": 1,
    }


_RUN = (
    "import json, sys\n"
    "import cv2\n"
    "import pycolmap\n"
    "ws, opts = sys.argv[1], json.load(open(sys.argv[2]))\n"
    "o = pycolmap.PatchMatchOptions()\n"
    "for k, v in opts.items():\n"
    "    setattr(o, k, v)\n"
    "pycolmap.patch_match_stereo(ws, workspace_format='COLMAP', pmvs_option_name='option-all',\n"
    "                            options=o)\n"
)


def read_colmap_array(path: str | Path) -> np.ndarray:
    """COLMAP's dense array format: ``width&height&channels&`` then float32, channel by
    channel, row after row (``Mat::Get(row, col, slice)``)."""
    data = Path(path).read_bytes()
    head = []
    pos = 0
    for _ in range(3):
        j = data.index(b"&", pos)
        head.append(int(data[pos:j]))
        pos = j + 1
    w, h, c = head
    arr = np.frombuffer(data, dtype=np.float32, offset=pos, count=w * h * c)
    arr = arr.reshape((c, h, w)).transpose(1, 2, 0)
    return arr[..., 0] if c == 1 else arr


def colmap_depth(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                 src_imgs: list[np.ndarray], near: float, far: float, workspace: str | Path,
                 opt: ColmapOptions | None = None) -> np.ndarray:
    """Z-depth of the reference by patch-match stereo (0 invalid)."""
    opt = opt or ColmapOptions()
    ok, why = colmap_available()
    if not ok:
        raise DepthBackendError(f"depth backend 'colmap' cannot run here ({why}): {COLMAP_HINT}")
    ws = Path(workspace)
    names = prepare_workspace(ws, ref, ref_img, srcs, src_imgs)
    opts = patch_match_options(near, far, max(ref.width, ref.height), opt)
    write_json(ws / "patch_match_options.json", opts)
    cmd = [sys.executable, "-c", _RUN, str(ws), str(ws / "patch_match_options.json")]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=opt.timeout_s)
    if out.returncode != 0:
        tail = "\n".join((out.stdout + out.stderr).splitlines()[-20:])
        raise DepthBackendError(f"pycolmap patch_match_stereo failed (exit {out.returncode}) in "
                                f"{ws}:\n{tail}")
    dm = ws / "stereo" / "depth_maps" / f"{names[0]}.photometric.bin"
    if opt.geom_consistency:
        dm = dm.with_name(f"{names[0]}.geometric.bin")
    depth = read_colmap_array(dm)
    if depth.shape != (ref.height, ref.width):
        raise DepthBackendError(f"{dm}: depth map is {depth.shape[1]}x{depth.shape[0]}, expected "
                                f"{ref.width}x{ref.height}")
    depth = np.where((depth >= near) & (depth <= far), depth, 0.0)
    return depth.astype(np.float32)
