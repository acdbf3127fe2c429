"""How much the captures say about the focal length (issue 32): why the refined focal length
misses 0.1 % on some captures, measured rather than guessed.

Two parts.

1. **The pattern a focal error leaves** (no data): a view of the captures' size and focal
   length turned by a hand-held shot's angle about its vertical axis. With the focal length
   off by ``e``, the best turn and shift explain the same pixels up to a residual pattern;
   its largest and rms size is what the observations must resolve to fix the focal length
   to ``e``. (A parallel array fixes nothing: the focal length trades off against depth.)
2. **What moves it on real observations** (per kept capture of ``bench_accuracy.py``):
   each of the refinement's points (:func:`plenocal.calib.track_sets.select_points`) is
   triangulated with the true cameras; an observation's residual is its offset from the
   true projection. Observations more than ``--within`` px off (mismatches) are dropped
   from every run below, so that only small, honest errors are left. The refinement
   (the workflow's settings) then runs on observations that are

   * ``measured``: as the features put them;
   * ``exact``: the true projections (the solver's own bias: it must come out 0);
   * ``hand only``: the true projections plus the measured residuals of the hand-held
     shots' views (the array's exact);
   * ``array only``: the other way round;
   * ``shuffled``: the true projections plus the same residuals, dealt out at random
     (their sizes kept, their pattern broken).

   and the residuals' own structure per shot is fitted: an affine map and a projective
   term of the view coordinates (px at 300 px from the principal point).

Usage::

    python bench/bench_focal_information.py [--captures default-s3 wide-s3 ...]
        [--within 0.3] [--out BENCHMARKS.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md)
import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_accuracy import require_kept_capture  # noqa: E402
from benchmd import Lines, update_sections  # noqa: E402

from plenocal.artifacts.cameras import read_cameras  # noqa: E402
from plenocal.artifacts.rig import RigB, read_rig  # noqa: E402
from plenocal.calib import refine as rf  # noqa: E402
from plenocal.calib import track_sets as tsets  # noqa: E402
from plenocal.calib.reg_b.rig import rig_at_focal  # noqa: E402
from plenocal.config import validate_config  # noqa: E402
from plenocal.names import array_shots, split_key  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out" / "accuracy"
RUNS = ("measured", "exact", "hand only", "array only", "shuffled")  # "measured" first
TURNS_DEG = (5.0, 10.0)
FOCAL_ERRORS = (0.001, 0.002)


# ---------------------------------------------------------------- part 1: the pattern


def _turned(f: float, theta: float, x: np.ndarray, y: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (x, y) (from the principal point) of a view of focal length ``f`` seen by the
    same view turned by ``theta`` (rad) about its vertical axis."""
    c, s = np.cos(theta), np.sin(theta)
    zx = c * x + s * f
    zz = -s * x + c * f
    return f * zx / zz, f * y / zz


def focal_pattern(f: float, width: int, height: int, turn_deg: float, rel: float
                  ) -> tuple[float, float]:
    """(largest, rms) residual px left when a turn of ``turn_deg`` seen with the focal length
    ``f (1 + rel)`` is fitted to the truth by the turn and a shift (Gauss-Newton)."""
    x, y = np.meshgrid(np.linspace(-width / 2, width / 2, 81),
                       np.linspace(-height / 2, height / 2, 61))
    u0, v0 = _turned(f, np.deg2rad(turn_deg), x, y)
    f2 = f * (1.0 + rel)

    def residual(p: np.ndarray) -> np.ndarray:
        u, v = _turned(f2, p[0], x, y)
        return np.concatenate([(u + p[1] - u0).ravel(), (v + p[2] - v0).ravel()])

    p = np.array([np.deg2rad(turn_deg), 0.0, 0.0])
    for _ in range(20):
        r = residual(p)
        J = np.stack([(residual(p + d) - r) / 1e-7 for d in np.eye(3) * 1e-7], axis=1)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        p += step
        if np.abs(step).max() < 1e-12:
            break
    r = residual(p).reshape(2, -1)
    return float(np.abs(r).max()), float(np.sqrt((r ** 2).sum(axis=0).mean()))


# ---------------------------------------------------------------- part 2: the observations


def truth_residuals(tracks, ids: list[int], truth) -> dict[tuple[int, int], tuple]:
    """(image_id, point2D_idx) -> (true projection, residual), COLMAP's pixel convention, of
    every observation of the points ``ids``: each point triangulated with the true cameras
    (a linear DLT over its track, all points at once: each point's equations padded with
    zero rows to the longest track's, which leaves its null space as it is). The model is
    read back through COLMAP's binary files (:func:`plenocal.verify.reprojection.read_model`)."""
    from plenocal.verify import reprojection as rp  # noqa: PLC0415

    obs, _, _ = rp.read_model(tracks)
    want = np.asarray(sorted(ids), dtype=np.uint64)
    keys, point, uv, P = [], [], [], []
    for image_id in sorted(tracks.images):
        name = tracks.image(image_id).name
        kp, pid = obs[name]
        idx = np.flatnonzero(np.isin(pid, want))
        if not idx.size:
            continue
        cam = truth[name[:-4]]
        keys += [(image_id, int(i)) for i in idx]
        point.append(np.searchsorted(want, pid[idx]))
        uv.append(kp[idx] - 0.5)
        P.append(np.broadcast_to(cam.K @ cam.world_to_cam[:3], (idx.size, 3, 4)))
    point, uv, P = np.concatenate(point), np.concatenate(uv), np.concatenate(P)
    # each observation's two DLT rows, in the slot of its point's system
    eqs = uv[:, :, None] * P[:, 2:3, :] - P[:, :2, :]  # (n, 2, 4)
    order = np.argsort(point, kind="stable")
    counts = np.bincount(point, minlength=len(want))
    slot = np.empty(len(point), np.intp)
    slot[order] = np.arange(len(point)) - np.repeat(np.cumsum(counts) - counts, counts)
    A = np.zeros((len(want), 2 * int(counts.max()), 4))
    A[point, 2 * slot] = eqs[:, 0]
    A[point, 2 * slot + 1] = eqs[:, 1]
    X = np.linalg.svd(A, full_matrices=False)[2][:, -1]
    Xh = X[point] / X[point, 3:]
    proj = np.einsum("nij,nj->ni", P, Xh)
    proj = proj[:, :2] / proj[:, 2:]
    return {k: (proj[n] + 0.5, uv[n] - proj[n]) for n, k in enumerate(keys)}


def _rebuilt(rec, xy: dict, keep: set, point_ids: list[int], tracks):
    """``rec`` (a rig reconstruction) again, its observations moved to ``xy`` where given and
    its tracks cut to the observations in ``keep`` (points left with fewer than two
    dropped)."""
    import pycolmap  # noqa: PLC0415

    from plenocal.verify.reprojection import read_keypoints  # noqa: PLC0415

    moved: dict[int, list] = {}
    for (iid, k), uv in xy.items():
        moved.setdefault(iid, []).append((k, uv))
    keypoints = read_keypoints(rec)
    out = pycolmap.Reconstruction()
    for cid in rec.cameras:
        out.add_camera(rec.camera(cid))
    for rid in rec.rigs:
        out.add_rig(rec.rig(rid))
    for fid in rec.frames:
        old = rec.frame(fid)
        frame = pycolmap.Frame(frame_id=fid, rig_id=old.rig_id)
        frame.rig_from_world = old.rig_from_world
        for d in old.data_ids:
            frame.add_data_id(d)
        out.add_frame(frame)
    for iid in sorted(rec.images):
        im = rec.image(iid)
        kp = keypoints[im.name].copy()
        for k, uv in moved.get(iid, ()):
            kp[k] = uv
        new = pycolmap.Image(name=im.name, keypoints=kp, camera_id=im.camera_id,
                             image_id=iid)
        new.frame_id = im.frame_id
        out.add_image(new)
    for fid in rec.frames:
        out.register_frame(fid)
    for pid in point_ids:
        p = tracks.point3D(pid)
        els = [e for e in p.track.elements if (e.image_id, e.point2D_idx) in keep]
        if len(els) >= 2:
            out.add_point3D(p.xyz, pycolmap.Track(els))
    return out


def shots_of_images(tracks) -> dict[int, str]:
    """image_id -> its shot (``<shot>/<view>.png``)."""
    return {iid: split_key(tracks.image(iid).name[:-4])[0] for iid in tracks.images}


def residual_structure(tracks, res: dict, keep: set) -> dict[str, np.ndarray]:
    """shot -> the least-squares fit of its kept residuals (px) by a shift, an affine map and
    a projective term of the view coordinates (in units of 300 px from the principal
    point): [shift x, x/x, x/y, shift y, y/x, y/y, proj a, proj b], and the median."""
    shot_of = shots_of_images(tracks)
    pp_of = {}
    for iid in tracks.images:
        cam = tracks.camera(tracks.image(iid).camera_id)
        pp_of[iid] = (cam.principal_point_x, cam.principal_point_y)
    by_shot: dict[str, list] = {}
    for key in sorted(keep):
        by_shot.setdefault(shot_of[key[0]], []).append(key)
    out = {}
    for shot, keys in sorted(by_shot.items()):
        cam_pp = np.array([pp_of[k[0]] for k in keys])
        proj = np.array([res[k][0] for k in keys])
        r = np.array([res[k][1] for k in keys])
        x, y = ((proj - cam_pp) / 300.0).T
        A = np.zeros((2 * len(keys), 8))
        A[0::2, 0], A[0::2, 1], A[0::2, 2] = 1, x, y
        A[1::2, 3], A[1::2, 4], A[1::2, 5] = 1, x, y
        A[0::2, 6], A[0::2, 7] = x * x, x * y
        A[1::2, 6], A[1::2, 7] = x * y, y * y
        fit = np.linalg.lstsq(A, r.ravel(), rcond=None)[0]
        out[shot] = np.append(fit, np.median(np.linalg.norm(r, axis=1)))
    return out


@dataclasses.dataclass
class KeptCapture:
    """A kept capture of ``bench_accuracy.py`` as its refinement and its truth see it."""

    name: str
    res: Path  # its results/synthetic
    cfg: dict  # its config, validated
    settings: rf.RefineSettings
    eq6: dict
    truth: dict
    rig: RigB
    hold: str  # the shot the workflow holds: the array's middle one (full_set_cam)
    f_true: float  # px


def kept_capture(capture: str) -> KeptCapture:
    """``bench/out/accuracy/<capture>`` read as the workflow's rule ``refine`` reads it."""
    res = OUT / capture / "results" / "synthetic"
    cfg = validate_config(yaml.safe_load((OUT / capture / "config.yaml").read_text()))
    # the view database's tracks, whose observations this bench studies (refine.tracks)
    settings = dataclasses.replace(
        rf.RefineSettings.from_config(cfg["refine"], seed=int(cfg["sfm"]["seed"])),
        tracks="views")
    truth = read_cameras(res / "ground_truth" / "cameras.json")
    rig = read_rig(res / "reg_b" / "rig.json")
    sim = cfg["datasets"]["synthetic"]["simulate"]["array"]
    array = array_shots(int(sim["cols"]), int(sim["rows"]))  # row-major, as the workflow's
    hold = array[len(array) // 2]
    central = [v for v, (_, M) in rig.view_poses().items() if np.allclose(M, np.eye(4))][0]
    return KeptCapture(capture, res, cfg, settings,
                       read_cameras(res / "calibration" / "eq6" / "cameras.json"), truth, rig,
                       hold, float(truth[f"{hold}/{central}"].K[0, 0]))


def refine_runs(cap: KeptCapture, runs: list[str], rebuild) -> dict:
    """The workflow's refinement of ``cap`` once per run of ``runs``, each on the rig
    reconstruction ``rebuild(run, rec, tracks, point_ids)`` returns, every run at the first
    run's robust scale (``auto`` would follow each run's own median error, and weigh the
    runs' residuals differently). Returns ``runs`` (run -> signed focal error %),
    ``median`` (run -> median reprojection error after, px) and ``loss_scale``."""
    original = tsets.rig_reconstruction
    state = {"run": runs[0]}

    def patched(tracks, views, shot_poses, width, height, point_ids, work_dir=None,
                keypoints=None):
        rec, model = original(tracks, views, shot_poses, width, height, point_ids, work_dir,
                              keypoints)
        return rebuild(state["run"], rec, tracks, point_ids), model

    out: dict = {"runs": {}, "median": {}}
    settings = cap.settings
    tsets.rig_reconstruction = patched
    try:
        for how in runs:
            state["run"] = how
            if "loss_scale" in out:
                settings = dataclasses.replace(settings, loss_scale_px=out["loss_scale"])
            t0 = time.perf_counter()
            r = rf.refine_calibration(cap.eq6, cap.rig, cap.res / "matches" / "database.db",
                                      settings, hold_shot=cap.hold,
                                      rig_at_focal=lambda f: RigB(rig_at_focal(cap.rig.doc, f)))
            out.setdefault("loss_scale", float(r.report["loss"]["scale_px"]))
            out["runs"][how] = 100.0 * (r.report["focal_px"]["refined"] / cap.f_true - 1.0)
            out["median"][how] = float(r.report["observations"]["after"]["median_px"])
            print(f"{cap.name} {how:30s} focal {out['runs'][how]:+.3f} % "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
    finally:
        tsets.rig_reconstruction = original
    return out


def run(capture: str, within: float, runs: list[str]) -> dict:
    cap = kept_capture(capture)
    state: dict = {}

    def rebuild(how: str, rec, tracks, point_ids):
        if "res" not in state:
            state["res"] = truth_residuals(tracks, point_ids, cap.truth)
            state["keep"] = {k for k, (_, r) in state["res"].items()
                             if np.linalg.norm(r) <= within}
            state["structure"] = residual_structure(tracks, state["res"], state["keep"])
            state["shot_of"] = shots_of_images(tracks)
        res, keep = state["res"], state["keep"]
        keys = sorted(keep)
        if how == "measured":
            xy = {}
        elif how == "shuffled":
            deal = np.random.default_rng(0).permutation(len(keys))
            xy = {k: res[k][0] + res[keys[j]][1] for k, j in zip(keys, deal, strict=True)}
        else:
            def take(k: tuple) -> bool:
                hand = state["shot_of"][k[0]].startswith("hand")
                return (how == "hand only" and hand) or (how == "array only" and not hand)
            xy = {k: res[k][0] + (res[k][1] if take(k) else 0.0) for k in keys}
        return _rebuilt(rec, xy, keep, point_ids, tracks)

    out = {"runs": refine_runs(cap, runs, rebuild)["runs"]}
    kept = [np.linalg.norm(state["res"][k][1]) for k in state["keep"]]
    out["kept"] = (len(state["keep"]), len(state["res"]), float(np.median(kept)))
    out["structure"] = state["structure"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--captures", nargs="+", default=["default-s3", "wide-s3", "default-s8"])
    ap.add_argument("--within", type=float, default=0.3,
                    help="observations farther than this (px) from the truth are dropped")
    ap.add_argument("--runs", nargs="+", default=list(RUNS), choices=RUNS)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    for capture in args.captures:
        require_kept_capture(OUT / capture)
    lines = Lines()
    first = OUT / args.captures[0] / "results" / "synthetic" / "ground_truth" / "cameras.json"
    cam = next(iter(read_cameras(first).values()))
    f, w, h = float(cam.K[0, 0]), int(cam.width), int(cam.height)
    lines.say(f"The pattern a focal error leaves (a {w} x {h} px view, f = {f:.0f} px, turned "
              "about its vertical axis; the turn and a shift fitted again): largest / rms "
              "residual px")
    lines.say("")
    lines.say("| turn | " + " | ".join(f"focal {100 * e:.1f} % off" for e in FOCAL_ERRORS)
              + " |")
    lines.say("|---|" + "---:|" * len(FOCAL_ERRORS))
    for turn in TURNS_DEG:
        cells = [focal_pattern(f, w, h, turn, e) for e in FOCAL_ERRORS]
        lines.say(f"| {turn:.0f} deg | " + " | ".join(f"{a:.4f} / {b:.4f}" for a, b in cells)
                  + " |")
    results = {c: run(c, args.within, args.runs) for c in args.captures}
    lines.say("")
    lines.say(f"The refined focal length's error (%, signed) on observations within "
              f"{args.within} px of the truth:")
    lines.say("")
    lines.say("| capture | kept obs. (median px) | " + " | ".join(args.runs) + " |")
    lines.say("|---|---|" + "---:|" * len(args.runs))
    for cap, r in results.items():
        n, total, med = r["kept"]
        lines.say(f"| {cap} | {n} of {total} ({med:.3f}) | "
                  + " | ".join(f"{r['runs'][k]:+.3f}" for k in args.runs) + " |")
    lines.say("")
    lines.say("The residuals' structure per shot (px at 300 px from the principal point; "
              "largest over the shots of each kind): affine terms (x/x, x/y, y/x, y/y), "
              "projective terms, median residual:")
    lines.say("")
    lines.say("| capture | kind | affine | projective | median |")
    lines.say("|---|---|---:|---:|---:|")
    for cap, r in results.items():
        for kind in ("hand", "x"):
            fits = [v for s, v in r["structure"].items() if s.startswith(kind)]
            if not fits:
                continue
            F = np.abs(np.array(fits))
            lines.say(f"| {cap} | {'hand-held' if kind == 'hand' else 'array'} | "
                      f"{F[:, [1, 2, 4, 5]].max():.4f} | {F[:, 6:8].max():.4f} | "
                      f"{statistics.median(F[:, 8]):.3f} |")
    if args.out:
        update_sections(args.out, {"How much the captures say about the focal length "
                                   "(issue 32)": list(lines)})


if __name__ == "__main__":
    main()
