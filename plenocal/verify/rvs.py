"""MPEG's Reference View Synthesizer (RVS 4.0) as a renderer of the view-synthesis
experiments (``verify.renderer: rvs``), and its build from source.

RVS is not part of the project: its BSD-licensed source tarball (see the README's
"MPEG exports and RVS") is built once, outside the repository, into
``~/.cache/plenocal/rvs/<sha256 of the tarball>/RVS`` (``PLENOCAL_CACHE`` moves the
cache), with the recipe RVS needs on Debian: cmake, a C++ compiler and OpenCV's
development package, ``-DWITH_OPENGL=OFF -DCMAKE_CXX_STANDARD=14``.

One synthesis runs RVS once per target view on a temporary folder that holds the MPEG
camera JSON of the inputs and the target (:mod:`plenocal.export.mpeg`), the inputs'
textures as PNG and their depth as 16-bit PNG of normalised disparity
(:mod:`plenocal.export.depthmaps`), and an RVS configuration (Version 3.0); RVS reads
both PNG files natively (so odd view sizes need no 4:2:0 layout) and writes the
target as PNG.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from plenocal.camera import PinholeCamera
from plenocal.export.depthmaps import write_depth16_png
from plenocal.export.mpeg import mpeg_document
from plenocal.io.files import file_sha256, to_float, to_uint8, write_image, write_json

RVS_HINT = ("build RVS 4.0 from its source (README, 'MPEG exports and RVS'): "
            "python -m plenocal.verify.rvs <rvs-4.0-src.tar.gz>, and give the binary it "
            "prints as verify.rvs_binary")


class RvsError(RuntimeError):
    """RVS could not be built or did not produce its output."""


def cache_root() -> Path:
    base = os.environ.get("PLENOCAL_CACHE")
    return Path(base) if base else Path.home() / ".cache" / "plenocal"


def build_prerequisites() -> list[str]:
    """What the build needs and this machine lacks (empty when it can build)."""
    missing = [t for t in ("cmake", "make") if shutil.which(t) is None]
    if shutil.which("c++") is None and shutil.which("g++") is None:
        missing.append("a C++ compiler (g++)")
    if not any(Path(p).is_file() for p in (
            "/usr/lib/x86_64-linux-gnu/cmake/opencv4/OpenCVConfig.cmake",
            "/usr/lib/aarch64-linux-gnu/cmake/opencv4/OpenCVConfig.cmake",
            "/usr/local/lib/cmake/opencv4/OpenCVConfig.cmake",
            "/usr/share/OpenCV/OpenCVConfig.cmake")):
        missing.append("OpenCV's development package (libopencv-dev)")
    return missing


def build_rvs(tarball: str | Path, root: str | Path | None = None, jobs: int = 2) -> Path:
    """Path of the RVS binary built from ``tarball`` (cached by the tarball's hash; the
    cache entry appears only once the build succeeded)."""
    tarball = Path(tarball)
    if not tarball.is_file():
        raise RvsError(f"RVS source {tarball} does not exist; {RVS_HINT}")
    dest = Path(root) if root else cache_root() / "rvs" / file_sha256(tarball)[:16]
    binary = dest / "RVS"
    if binary.is_file():
        return binary
    missing = build_prerequisites()
    if missing:
        raise RvsError(f"cannot build RVS from {tarball}: missing {', '.join(missing)} "
                       "(Debian: apt-get install cmake g++ libopencv-dev)")
    dest.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="rvs-build-", dir=dest.parent) as tmp:
        tmp = Path(tmp)
        subprocess.run(["tar", "xzf", str(tarball), "-C", str(tmp)], check=True)
        srcs = [p.parent for p in tmp.glob("*/CMakeLists.txt")]
        if len(srcs) != 1:
            raise RvsError(f"{tarball}: expected one source folder with a CMakeLists.txt")
        build = tmp / "build"
        log = tmp / "build.log"
        with open(log, "w") as out:
            steps = [["cmake", "-S", str(srcs[0]), "-B", str(build), "-DWITH_OPENGL=OFF",
                      "-DCMAKE_BUILD_TYPE=Release", "-DCMAKE_CXX_STANDARD=14"],
                     ["make", "-C", str(build), f"-j{jobs}", "RVS"]]
            for cmd in steps:
                if subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT).returncode:
                    tail = log.read_text()[-3000:]
                    raise RvsError(f"building RVS from {tarball} failed at "
                                   f"'{' '.join(cmd[:2])}':\n{tail}")
        stage = tmp / "stage"
        stage.mkdir()
        shutil.copy2(build / "RVS", stage / "RVS")
        try:
            stage.rename(dest)
        except OSError:  # built meanwhile by another process
            if not binary.is_file():
                raise
    return binary


def rvs_config(input_names: Sequence[str], target_names: Sequence[str],
               textures: Sequence[str], depths: Sequence[str], outputs: Sequence[str],
               camera_file: str, blending_factor: float = 5.0) -> dict:
    """An RVS view-synthesis configuration (Version 3.0), paths relative to where RVS
    runs."""
    return {
        "Version": "3.0",
        "InputCameraParameterFile": camera_file,
        "VirtualCameraParameterFile": camera_file,
        "InputCameraNames": list(input_names),
        "VirtualCameraNames": list(target_names),
        "ViewImageNames": list(textures),
        "DepthMapNames": list(depths),
        "OutputFiles": list(outputs),
        "StartFrame": 0,
        "NumberOfFrames": 1,
        "Precision": 1.0,
        "ColorSpace": "RGB",
        "ViewSynthesisMethod": "Triangles",
        "BlendingMethod": "Simple",
        "BlendingFactor": float(blending_factor),
    }


def run_rvs(binary: str | Path, config: str | Path, cwd: str | Path, timeout: float = 600) -> str:
    """Run ``RVS config --noopengl`` in ``cwd``; its output text."""
    binary = Path(binary)
    if not binary.is_file():
        raise RvsError(f"verify.rvs_binary: {binary} does not exist; {RVS_HINT}")
    p = subprocess.run([str(binary.resolve()), str(config), "--noopengl"], cwd=cwd,
                       capture_output=True, text=True, timeout=timeout)
    if p.returncode:
        raise RvsError(f"RVS ({binary}) failed on {Path(cwd) / config} with exit code "
                       f"{p.returncode}:\n{(p.stdout + p.stderr)[-3000:]}")
    return p.stdout


def rvs_synthesize(binary: str | Path, inputs: Sequence[tuple[str, PinholeCamera, np.ndarray,
                                                              np.ndarray]],
                   targets: Sequence[tuple[str, PinholeCamera]], depth_range: tuple[float, float],
                   blending_factor: float = 5.0) -> dict[str, np.ndarray]:
    """Targets rendered by RVS from ``inputs`` = (name, camera, image, z-depth) as float32
    RGB in [0, 1]; names are MPEG camera names (no '/'). One RVS run for all targets."""
    near, far = depth_range
    with tempfile.TemporaryDirectory(prefix="plenocal-rvs-") as tmp:
        tmp = Path(tmp)
        cams = {n: c for n, c, _, _ in inputs}
        cams.update(dict(targets))
        write_json(tmp / "cameras.json", mpeg_document(cams, (near, far)))
        tex, dep = [], []
        for name, _, img, z in inputs:
            write_image(tmp / f"{name}.png", to_uint8(to_float(img)))
            write_depth16_png(tmp / f"{name}_depth.png", z, near, far)
            tex.append(f"{name}.png")
            dep.append(f"{name}_depth.png")
        outs = [f"out_{n}.png" for n, _ in targets]
        cfg = rvs_config([n for n, *_ in inputs], [n for n, _ in targets], tex, dep, outs,
                         "cameras.json", blending_factor)
        write_json(tmp / "rvs.json", cfg)
        run_rvs(binary, "rvs.json", tmp)
        result = {}
        for (name, cam), out in zip(targets, outs, strict=True):
            img = cv2.imread(str(tmp / out), cv2.IMREAD_COLOR)
            if img is None:
                raise RvsError(f"RVS wrote no {out} for target {name}")
            if img.shape[:2] != (cam.height, cam.width):
                raise RvsError(f"RVS output {out} is {img.shape[1]}x{img.shape[0]}, the "
                               f"camera {name} is {cam.width}x{cam.height}")
            result[name] = img[..., ::-1].astype(np.float32) / 255.0
        return result


if __name__ == "__main__":
    import sys

    if len(sys.argv) != 2:
        sys.exit("usage: python -m plenocal.verify.rvs <rvs-4.0-src.tar.gz>")
    print(build_rvs(sys.argv[1]))
