"""Quality of the converted views against the simulator's ideal pinhole renders.

PSNR and SSIM (:mod:`skimage.metrics`, RGB, data range 255) per view, excluding a
border of one tile (``T`` pixels), where the outermost tiles have fewer neighbours to
blend with. Targets (issue 3): mean PSNR of the central views >= 30 dB, no view
< 27 dB.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from plenocal.convert.errors import ConvertError
from plenocal.io.files import read_image

CENTRAL_TARGET_DB = 30.0
MIN_TARGET_DB = 27.0


def _rgb8(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint16:
        img = np.rint(img / 257.0).astype(np.uint8)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    return img


def view_quality(view: np.ndarray, truth: np.ndarray, border: int) -> dict:
    """PSNR (dB) and SSIM of one view against its ideal render, inside the border."""
    view, truth = _rgb8(view), _rgb8(truth)
    if view.shape != truth.shape:
        raise ConvertError(f"view is {view.shape[1]}x{view.shape[0]}, its ground-truth render "
                           f"{truth.shape[1]}x{truth.shape[0]}: were both made with the same "
                           "convert settings?")
    b = int(border)
    if 2 * b >= min(view.shape[:2]):
        b = 0
    a = view[b:view.shape[0] - b, b:view.shape[1] - b]
    t = truth[b:truth.shape[0] - b, b:truth.shape[1] - b]
    psnr = peak_signal_noise_ratio(t, a, data_range=255)
    ssim = structural_similarity(t, a, data_range=255, channel_axis=2)
    return {"psnr_db": float(min(psnr, 99.0)), "ssim": float(ssim)}


def dataset_quality(pairs: Iterable[tuple[str, str, str | Path, str | Path]], border: int,
                    central: str) -> dict:
    """``pairs``: (cam, view, converted png, ground-truth png). Per cam, per view, plus
    the means and the verdict against the targets."""
    per: dict[str, dict[str, dict]] = {}
    for cam, view, mine, truth in pairs:
        per.setdefault(cam, {})[view] = view_quality(read_image(mine), read_image(truth), border)
    return summarise(per, central) | {"border_px": int(border)}


def summarise(per: Mapping[str, Mapping[str, Mapping]], central: str) -> dict:
    every = [v for cam in per.values() for v in cam.values()]
    centre = [cam[central] for cam in per.values() if central in cam]
    worst = min(every, key=lambda v: v["psnr_db"]) if every else None
    worst_name = next((f"{c}/{n}" for c, views in per.items() for n, v in views.items()
                       if v is worst), None)

    def mean(vals: list[Mapping], key: str) -> float | None:
        return float(np.mean([v[key] for v in vals])) if vals else None

    mean_central = mean(centre, "psnr_db")
    min_all = worst["psnr_db"] if worst else None
    return {
        "per_view": {c: dict(v) for c, v in per.items()},
        "mean_psnr_db": mean(every, "psnr_db"),
        "mean_ssim": mean(every, "ssim"),
        "mean_psnr_central_db": mean_central,
        "mean_ssim_central": mean(centre, "ssim"),
        "min_psnr_db": min_all,
        "worst_view": worst_name,
        "views": len(every),
        "central_view": central,
        "targets": {"mean_psnr_central_db": CENTRAL_TARGET_DB, "min_psnr_db": MIN_TARGET_DB},
        "meets_targets": bool(mean_central is not None and min_all is not None
                              and mean_central >= CENTRAL_TARGET_DB
                              and min_all >= MIN_TARGET_DB),
    }
