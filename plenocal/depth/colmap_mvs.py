"""Depth by COLMAP's patch-match stereo (pycolmap), run in a subprocess.

The CUDA build of pycolmap (``pycolmap-cuda12``) aborts the whole process where no
GPU is visible, and the CPU wheel raises, so the work runs in a child process and
:func:`plenocal.gpu.cuda_available` probes first. The workspace is COLMAP's dense
layout::

    <ws>/images/<name>.png           reference and sources
    <ws>/sparse/{cameras,images,points3D}.txt   PINHOLE cameras, known poses, no points
    <ws>/stereo/patch-match.cfg      reference, then its source images listed explicitly
    <ws>/stereo/{depth_maps,normal_maps,consistency_graphs}/

Depth bounds are given explicitly (no sparse points needed) and the minimum
triangulation angles are lowered for the small baselines of subaperture views.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.camera import PinholeCamera, k_to_colmap
from plenocal.config import stage_defaults
from plenocal.gpu import CUDA_HINT, GpuUnavailableError, cuda_available
from plenocal.io.files import atomic_write_text, to_float, to_uint8, write_image, write_json


class DepthBackendError(GpuUnavailableError):
    """A depth backend that cannot run here (or COLMAP's patch-match that failed)."""


COLMAP_HINT = f"{CUDA_HINT}, or use depth.backend: planesweep"


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


def colmap_available() -> tuple[bool, str]:
    """(can run, why not): :func:`plenocal.gpu.cuda_available` (a CUDA pycolmap and a
    GPU, probed once per process in a child process)."""
    return cuda_available()


def image_name(index: int) -> str:
    return f"view{index:03d}.png"


@dataclass(frozen=True)
class MvsProblem:
    """One reference view's depth: its camera and image, its sources', and its bounds."""
    ref: PinholeCamera
    ref_img: np.ndarray
    srcs: list[PinholeCamera]
    src_imgs: list[np.ndarray]
    near: float
    far: float


def _view_table(problems: list[MvsProblem]) -> tuple[list[tuple[PinholeCamera, np.ndarray]],
                                                     list[list[int]]]:
    """The distinct views of ``problems`` (an image array and its camera, once each,
    however many maps it serves) and, per problem, the indices of its reference and
    sources in that list."""
    views: list[tuple[PinholeCamera, np.ndarray]] = []
    index: dict[tuple, int] = {}
    per_problem = []
    for pb in problems:
        ids = []
        for cam, img in zip([pb.ref, *pb.srcs], [pb.ref_img, *pb.src_imgs], strict=True):
            key = (id(img), cam.K.tobytes(), cam.cam_to_world.tobytes(), cam.width,
                   cam.height)
            if key not in index:
                index[key] = len(views)
                views.append((cam, img))
            ids.append(index[key])
        per_problem.append(ids)
    return views, per_problem


def prepare_workspace(ws: str | Path, ref: PinholeCamera, ref_img: np.ndarray,
                      srcs: list[PinholeCamera], src_imgs: list[np.ndarray]) -> list[str]:
    """Write the dense workspace of one reference; returns the image names (reference
    first)."""
    names = prepare_workspace_many(ws, [MvsProblem(ref, ref_img, srcs, src_imgs, 0.0, 1.0)])
    return names[0]


def prepare_workspace_many(ws: str | Path, problems: list[MvsProblem]) -> list[list[str]]:
    """Write one dense workspace for all ``problems``: every distinct view once, and
    patch-match.cfg with each reference followed by its sources. Returns, per problem,
    the image names of its reference and sources."""
    import cv2  # noqa: PLC0415,F401  (cv2 before anything that imports pycolmap)

    ws = Path(ws)
    views, per_problem = _view_table(problems)
    names = [image_name(i) for i in range(len(views))]
    for name, (_, img) in zip(names, views, strict=True):
        im = np.asarray(img)
        write_image(ws / "images" / name, im if im.dtype in (np.uint8, np.uint16)
                    else to_uint8(to_float(im)))
    cam_lines = ["# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
    img_lines = ["# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME", "# POINTS2D[]"]
    for i, ((c, _), name) in enumerate(zip(views, names, strict=True), start=1):
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
    # patch-match.cfg: each reference, then its sources listed explicitly
    out = [[names[i] for i in ids] for ids in per_problem]
    refs = list(dict.fromkeys(n[0] for n in out))
    if len(refs) != len(out):
        raise ValueError("colmap depth: a reference view appears twice in one workspace")
    cfg = "".join(f"{n[0]}\n{', '.join(n[1:])}\n" for n in out)
    atomic_write_text(ws / "stereo" / "patch-match.cfg", cfg)
    atomic_write_text(ws / "stereo" / "fusion.cfg", "".join(f"{r}\n" for r in refs))
    return out


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


def colmap_depths(problems: list[MvsProblem], workspace: str | Path,
                  opt: ColmapOptions | None = None) -> list[np.ndarray]:
    """Z-depth of every problem's reference by patch-match stereo (0 invalid), in one
    COLMAP run: one child process, one pycolmap import and one CUDA context for all the
    maps of a job (issue 15: a process per map spent most of its 4-10 s starting). The
    run searches the union of the problems' bounds; each map then keeps the depths within
    its own."""
    opt = opt or ColmapOptions()
    if not problems:
        return []
    ok, why = colmap_available()
    if not ok:
        raise DepthBackendError(f"depth backend 'colmap' cannot run here ({why}): {COLMAP_HINT}")
    ws = Path(workspace)
    names = prepare_workspace_many(ws, problems)
    size = max(max(p.ref.width, p.ref.height) for p in problems)
    opts = patch_match_options(min(p.near for p in problems), max(p.far for p in problems),
                               size, opt)
    write_json(ws / "patch_match_options.json", opts)
    cmd = [sys.executable, "-c", _RUN, str(ws), str(ws / "patch_match_options.json")]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=opt.timeout_s)
    if out.returncode != 0:
        tail = "\n".join((out.stdout + out.stderr).splitlines()[-20:])
        raise DepthBackendError(f"pycolmap patch_match_stereo failed (exit {out.returncode}) in "
                                f"{ws}:\n{tail}")
    kind = "geometric" if opt.geom_consistency else "photometric"
    depths = []
    for pb, pb_names in zip(problems, names, strict=True):
        dm = ws / "stereo" / "depth_maps" / f"{pb_names[0]}.{kind}.bin"
        if not dm.is_file():
            raise DepthBackendError(f"{dm}: COLMAP wrote no depth map for this reference")
        depth = read_colmap_array(dm)
        if depth.shape != (pb.ref.height, pb.ref.width):
            raise DepthBackendError(f"{dm}: depth map is {depth.shape[1]}x{depth.shape[0]}, "
                                    f"expected {pb.ref.width}x{pb.ref.height}")
        depths.append(np.where((depth >= pb.near) & (depth <= pb.far), depth, 0.0)
                      .astype(np.float32))
    return depths
