"""Where COLMAP's CUDA code can run, and which device a COLMAP step uses.

COLMAP's GPU paths (SiftGPU, the GPU matcher, patch-match stereo) need a CUDA build of
pycolmap (``pycolmap-cuda12``, README "GPU") and a visible NVIDIA GPU. That build aborts
the whole process where no GPU is visible, and the CPU wheel has no CUDA code at all, so
:func:`cuda_available` asks a child process; its answer is kept for the life of this
process. Without ``nvidia-smi`` on the PATH the answer is known at once (no GPU
visible): a CPU machine spends no time on the probe.

The config's ``auto`` (``sfm.device``, ``depth.backend``) takes the GPU where the probe
says yes and the CPU path elsewhere; an explicit ``cuda`` where the probe says no is an
error that names the key, the reason and the remedy.
"""

from __future__ import annotations

import functools
import shutil
import subprocess
import sys

CUDA_HINT = "install pycolmap-cuda12 (README, GPU) and run on a GPU node"


class GpuUnavailableError(RuntimeError):
    """The config asks for COLMAP's CUDA code where it cannot run."""


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


@functools.cache
def cuda_available() -> tuple[bool, str]:
    """(COLMAP's CUDA code can run here, why not): a CUDA build of pycolmap and a GPU
    that ``nvidia-smi`` lists, probed in a child process (see the module's docstring);
    the answer is cached for this process (``cuda_available.cache_clear()`` forgets it)."""
    if shutil.which("nvidia-smi") is None:
        return False, "nvidia-smi not found: no GPU visible"
    try:
        out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                             timeout=120)
    except subprocess.TimeoutExpired:
        return False, "probing pycolmap timed out"
    lines = out.stdout.strip().splitlines() or out.stderr.strip().splitlines() or ["failed"]
    return out.returncode == 0, lines[-1]


def resolve_auto(name: str, key: str, cpu: str, gpu: str,
                 error: type[RuntimeError] = GpuUnavailableError) -> str:
    """The choice of the config's value ``name`` at ``key`` between a CPU path ``cpu``
    and COLMAP's CUDA path ``gpu``: ``auto`` -> ``gpu`` where :func:`cuda_available`, else
    ``cpu``; ``cpu`` as it is; ``gpu`` where it cannot run -> ``error``, naming the key,
    the reason and the remedy."""
    if name == cpu:
        return name
    if name not in ("auto", gpu):
        raise ValueError(f"config: {key} = {name!r}: must be auto, {cpu} or {gpu}")
    ok, why = cuda_available()
    if ok:
        return gpu
    if name == gpu:
        raise error(f"config: {key} = {gpu}, but COLMAP's CUDA code cannot run here ({why}): "
                    f"{CUDA_HINT}, or set {key}: auto or {cpu}")
    return cpu


def resolve_device(name: str, key: str = "sfm.device") -> str:
    """The device of a COLMAP step (config ``sfm.device``): ``cpu`` or ``cuda``
    (:func:`resolve_auto`)."""
    return resolve_auto(name, key, "cpu", "cuda")
