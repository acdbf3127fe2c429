"""The view-synthesis experiments of Section III (Figs. 6-9), as functions of a
calibration (cameras dict ``"<cam>/<view>" -> PinholeCamera``), the captured views
and the ``verify`` config, so that the same experiment runs on the complete
calibration and on the ground-truth cameras (the dB lost to calibration).

For each experiment: every input view has one z-depth map (given - the workflow
computes them once with the complete calibration, :mod:`plenocal.depth.views` - or,
when not given, estimated here with the calibration under test, by SGM over the
plane-sweep cost volume), the targets are rendered from the inputs by the project's
DIBR (:mod:`plenocal.verify.dibr`) or by MPEG's RVS (``verify.renderer: rvs``,
:mod:`plenocal.verify.rvs`), and each is scored by PSNR against the captured
(converted) view, excluding a border. The dB lost to calibration compares the two
camera sets with one and the same depth maps.

- Exp. 1 (Fig. 6a / 7): central view of every array shot from the central views of
  the four corner shots; grid = array rows x cols.
- Exp. 2 (Fig. 6b / 8): every view of an N x N set from the middle views of its four
  sides; one grid N x N per set.
- Exp. 3 (Fig. 6c, d / 9): every view of every array shot from the corner shots'
  central views (a) and from their lateral views (b), "lateral" being the view of
  each corner set nearest the array centre (the inner corner view, Fig. 6d); grid =
  (rows N) x (cols N), the views of shot (x, y) in block (y, x).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from plenocal.artifacts.results import (
    CAMERA_SETS,
    DEPTHS,
    DepthQuality,
    PsnrTable,
    SynthesisResult,
    SynthesisRuns,
    SynthesisSetup,
    SynthImage,
)
from plenocal.camera import PinholeCamera
from plenocal.config import settings_from, with_defaults
from plenocal.depth.quality import depth_quality
from plenocal.depth.views import estimate_view_depth
from plenocal.export.mpeg import mpeg_name
from plenocal.io.files import read_image, to_float
from plenocal.names import (
    key_shot,
    split_key,
)
from plenocal.verify.dibr import DibrOptions, PreparedView, View, prepare_view, synthesize
from plenocal.verify.experiments import (
    ArrayLayout,
    all_views,
    experiment_plan,
)
from plenocal.verify.scores import error_rings, psnr_from_rings
from plenocal.verify.surface import masked_error, psnr_of_error, surface_mask

log = logging.getLogger(__name__)


#: targets rendered by the DIBR per core before they are scored and dropped
#: (:meth:`SynthesisContext.score`)
SCORE_CHUNK = 8


def synthesis_config(config: Mapping) -> dict:
    """The settings of the synthesis experiments, partial or whole, with the schema's
    defaults filled in: the config's ``verify`` block, its ``depth`` block under
    ``"depth"``, and the job's cores under ``"threads"`` (kept as given; none: one)."""
    verify = {k: v for k, v in config.items() if k not in ("depth", "threads")}
    out = with_defaults("verify", verify)
    out["depth"] = with_defaults("depth", config.get("depth"))
    if "threads" in config:
        out["threads"] = config["threads"]
    return out


@dataclass
class SynthesisContext:
    """What every experiment needs, for one calibration (``config``: see
    :func:`synthesis_config`, which fills it)."""
    cameras: dict[str, PinholeCamera]
    image_path: Callable[[str, str], str]
    layout: ArrayLayout
    near: float
    far: float
    config: dict = field(default_factory=dict)
    depths: dict[str, np.ndarray] = field(default_factory=dict)
    _images: dict = field(default_factory=dict)
    #: target -> its surface pixels (plenocal.verify.surface): scored there too
    surface_masks: dict[str, np.ndarray] = field(default_factory=dict)
    _prepared: dict[str, PreparedView] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.config = synthesis_config(self.config)

    @property
    def workers(self) -> int:
        """Threads for the targets (``config["threads"]``: the job's cores)."""
        return max(1, int(self.config.get("threads", 1)))

    def camera(self, key: str) -> PinholeCamera:
        if key not in self.cameras:
            raise KeyError(f"synthesis: view {key} is not in the calibration; was it "
                           "registered? (check the calibration's cameras.json)")
        return self.cameras[key]

    def image(self, key: str) -> np.ndarray:
        """The captured view ``key`` (read once; the cache may be shared by the runs of
        an experiment with other camera sets, so the size is checked on every call)."""
        cam, view = split_key(key)
        if key not in self._images:
            self._images[key] = to_float(read_image(self.image_path(cam, view)))
        img = self._images[key]
        c = self.camera(key)
        if img.shape[:2] != (c.height, c.width):
            raise ValueError(f"synthesis: {self.image_path(cam, view)} is "
                             f"{img.shape[1]}x{img.shape[0]}, its camera says "
                             f"{c.width}x{c.height}")
        return img

    def depth(self, key: str) -> np.ndarray:
        """The depth map of ``key``: the given one, else estimated with this calibration."""
        if key not in self.depths:
            d, srcs = estimate_view_depth(
                key, self.cameras, self.image, self.near, self.far, self.layout.n_views,
                self.config["depth"], int(self.config["depth_sources_shots"]),
                int(self.config["depth_sources_set"]))
            log.info("depth of %s estimated from %s", key, ", ".join(srcs))
            self.depths[key] = d
        return self.depths[key]

    def prepared(self, key: str, opt: DibrOptions) -> PreparedView:
        """Input view ``key`` prepared for warping (dense depth, its discontinuities):
        once per input, shared by every target rendered from it."""
        if key not in self._prepared:
            self._prepared[key] = prepare_view(
                View(self.camera(key), self.image(key), self.depth(key)), opt)
        return self._prepared[key]

    def render(self, inputs: list[str], targets: list[str]) -> dict[str, np.ndarray]:
        """Every target rendered from the inputs by the configured renderer."""
        renderer = self.config["renderer"]
        if renderer == "dibr":
            opt = dibr_options(self.config)
            views = [self.prepared(k, opt) for k in inputs]
            cams = [self.camera(t) for t in targets]
            # targets are independent: the job's cores share them (the compiled warp and
            # blend release the GIL); map keeps the order, so the result is the same
            with ThreadPoolExecutor(self.workers) as pool:
                outs = pool.map(lambda c: synthesize(views, c, opt)[0], cams)
                return dict(zip(targets, outs, strict=True))
        if renderer != "rvs":
            raise ValueError(f"config: verify.renderer = {renderer!r}: must be dibr or rvs")
        from plenocal.verify.rvs import RvsError, rvs_synthesize  # noqa: PLC0415

        binary = self.config["rvs_binary"]
        if not binary:
            raise RvsError("config: verify.renderer is rvs but verify.rvs_binary is not "
                           "set; give the path of an RVS 4.0 binary (README, 'MPEG exports "
                           "and RVS')")
        ins = [(mpeg_name(k), self.camera(k), self.image(k), self.depth(k)) for k in inputs]
        outs = rvs_synthesize(binary, ins, [(mpeg_name(t), self.camera(t)) for t in targets],
                              (self.near, self.far),
                              float(self.config["rvs_blending_factor"]))
        return {t: outs[mpeg_name(t)] for t in targets}

    def score(self, inputs: list[str], targets: list[str],
              keep: set[str] | None = None) -> tuple[dict[str, dict], dict[str, np.ndarray]]:
        """Every target rendered from ``inputs`` and its errors against the captured
        view, per ring of pixels (:func:`plenocal.verify.scores.error_rings`: ``{"shape":
        [H, W(, C)], "sse": [...]}``, which :func:`psnr_tables` turns into the PSNR with
        the config's border), and the renders of ``keep``."""
        errors, kept = {}, {}
        # the DIBR's renders are scored a chunk at a time and dropped (Exp. 3 renders 189
        # targets a variant: all at once they held 0.75 GB at tile 8); RVS renders all the
        # targets of one call in one run of its own
        step = max(1, len(targets) if self.config["renderer"] != "dibr"
                   else SCORE_CHUNK * self.workers)
        for first in range(0, len(targets), step):
            chunk = targets[first:first + step]
            rendered = self.render(inputs, chunk)
            # reading the captured targets and their errors, on the job's cores (in order)
            with ThreadPoolExecutor(self.workers) as pool:
                for t, (out, sse, surface) in zip(
                        chunk, pool.map(self._compare, chunk, [rendered[t] for t in chunk]),
                        strict=True):
                    errors[t] = {"shape": list(out.shape), "sse": sse}
                    if surface is not None:
                        errors[t]["surface"] = list(surface)
                    log.info("synthesized %s: %.2f dB over the whole view", t,
                             psnr_from_rings(sse, out.shape))
                    if keep and t in keep:
                        kept[t] = out
        return errors, kept

    def _compare(self, t: str, out: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, tuple[float, int] | None]:
        """A target's render ``out`` (grey where the captured view is), its error rings
        against the captured view and its surface error where it has a surface mask."""
        truth = self.image(t)
        if out.ndim == 3 and truth.ndim == 2:
            out = out.mean(axis=2)
        mask = self.surface_masks.get(t)
        surface = None if mask is None else masked_error(out, truth, mask)
        return out, error_rings(out, truth), surface


def lateral_view(ctx: SynthesisContext, cam: str) -> str:
    """The view of shot ``cam``'s set whose camera centre is nearest the centre of the
    array's central views (the inner corner view of Fig. 6d), by the calibration under
    test."""
    L = ctx.layout
    cv = L.centre_view
    centres = [ctx.camera(f"{c}/{cv}").centre for c in L.cams if f"{c}/{cv}" in ctx.cameras]
    mid = np.mean(centres, axis=0)
    views = [v for v in all_views(L.n_views) if f"{cam}/{v}" in ctx.cameras]
    return min(views, key=lambda v: (float(np.linalg.norm(ctx.camera(f"{cam}/{v}").centre
                                                          - mid)), v))


def dibr_options(cfg: Mapping) -> DibrOptions:
    """DibrOptions from the config's ``verify`` block (its ``dibr`` settings), partial or
    whole."""
    return settings_from(DibrOptions, with_defaults("verify", cfg)["dibr"])


def _known(ctx: SynthesisContext, keys: list[str]) -> list[str]:
    return [k for k in keys if k in ctx.cameras]


def experiment1(ctx: SynthesisContext) -> tuple[dict, dict[str, np.ndarray]]:
    """Central views of every array shot from the corner shots' central views."""
    L = ctx.layout
    cv = L.centre_view
    inputs, targets = experiment_plan(L, 1)["exp1"]
    keep = {f"{L.middle_cam}/{cv}"}
    errors, kept = ctx.score(inputs, _known(ctx, targets), keep)
    return {"inputs": inputs, "errors": errors}, kept


def experiment2(ctx: SynthesisContext, cams: list[str]) -> tuple[dict, dict[str, np.ndarray]]:
    """Every view of the N x N sets of ``cams`` from the middle views of their sides."""
    L = ctx.layout
    sets, kept = {}, {}
    for cam in cams:
        inputs, targets = experiment_plan(L, 2, [cam])[f"exp2_{cam}"]
        errors, k = ctx.score(inputs, _known(ctx, targets), {f"{cam}/{L.centre_view}"})
        kept.update(k)
        sets[cam] = {"inputs": inputs, "errors": errors}
    return {"sets": sets}, kept


def experiment3(ctx: SynthesisContext, stride: int = 1) -> tuple[dict, dict[str, np.ndarray]]:
    """Every view of every array shot (every ``stride``-th view row/column, the centre
    always included) from the corner shots' central (a) and lateral (b) views."""
    L = ctx.layout
    plan = experiment_plan(L, 3, stride=stride, lateral=lambda c: lateral_view(ctx, c))
    result, kept = {}, {}
    for variant in ("central", "lateral"):
        inputs, targets = plan[f"exp3_{variant}"]
        keep = {f"{L.middle_cam}/{L.centre_view}"}
        errors, k = ctx.score(inputs, _known(ctx, targets), keep)
        kept.update({f"{variant}:{key}": img for key, img in k.items()})
        result[variant] = {"inputs": inputs, "errors": errors}
    result["view_stride"] = stride
    return result, kept


def run_experiment(exp: int, cameras: dict[str, PinholeCamera],
                   image_path: Callable[[str, str], str], layout: ArrayLayout, near: float,
                   far: float, config: dict,
                   depths: dict[str, np.ndarray] | None = None,
                   images: dict[str, np.ndarray] | None = None,
                   surface_masks: dict[str, np.ndarray] | None = None) -> tuple[
                       dict, dict[str, np.ndarray]]:
    """Experiment ``exp`` with one camera set and (optionally) given depth maps.
    ``images``: a cache of the captured views (``"<cam>/<view>"`` -> float image) shared
    by the runs of one experiment, which read the same views; ``surface_masks``: targets
    also scored over their surface pixels (:func:`surface_masks`)."""
    ctx = SynthesisContext(cameras, image_path, layout, near, far, config, dict(depths or {}),
                           images if images is not None else {},
                           surface_masks=dict(surface_masks or {}))
    if exp == 1:
        return experiment1(ctx)
    if exp == 2:
        return experiment2(ctx, layout.exp2_cams(ctx.config["exp2_sets"]))
    if exp == 3:
        return experiment3(ctx, int(ctx.config["exp3_view_stride"]))
    raise ValueError(f"synthesis: no experiment {exp} (1, 2 or 3)")


def synthesis_job(exp: int, cameras: dict[str, dict[str, PinholeCamera]],
                  depths: dict[str, dict[str, np.ndarray]],
                  image_path: Callable[[str, str], str], layout: ArrayLayout, near: float,
                  far: float, config: dict, threads: int = 1, synth_rel: str = "synth",
                  own_depths: Mapping[str, dict[str, np.ndarray]] | None = None
                  ) -> tuple[SynthesisResult, dict[str, np.ndarray]]:
    """One experiment of Fig. 6 as rule ``synthesis_exp<k>`` runs it: with every camera
    set of ``cameras`` (``complete``; on synthetic data also ``ground_truth``: their
    difference is the dB lost to calibration) and every depth of ``depths``
    (``estimated``: the inputs' maps of rule depth_view, made with the complete
    calibration; ``true``: the simulator's, the same for both sets, so their difference
    there is the dB lost to calibration alone, and the difference to ``estimated`` the dB
    lost to depth), by the configured renderer (``config["renderer"]``; RVS with the
    project's DIBR beside it unless ``rvs_compare_dibr`` is false). ``own_depths``:
    camera set -> its own estimated maps (``ground_truth``: rule depth_view_truth's, made
    with the true cameras, where verify.ground_truth_own_depth asks for them), which its
    ``estimated`` runs read; a set other than ``complete`` without its own maps renders
    with the true depth only. Depth estimated with one set's cameras fits that set's
    geometry, and scored another set on it (a calibration rotated 0.15 deg read 2.2 dB
    better than the truth on its maps).
    ``config``: the verify settings with the depth settings under ``"depth"``;
    ``threads``: the job's cores.

    Returns the typed result, whose images are named under ``synth_rel`` (the folder of
    the images relative to the result file), and the images kept for Fig. 10 by file
    name. :func:`synthesis_runs` and :func:`synthesis_result` are its two halves (Exp. 3
    runs each camera set in a job of its own)."""
    runs = synthesis_runs(exp, cameras, depths, image_path, layout, near, far, config,
                          threads, own_depths)
    return synthesis_result(runs, depths, near, far, config, synth_rel)


def surface_masks(exp: int, layout: ArrayLayout, truth: dict[str, PinholeCamera] | None,
                  true_depth: Mapping[str, np.ndarray] | None, config: Mapping
                  ) -> dict[str, np.ndarray]:
    """Target -> its surface pixels (:func:`plenocal.verify.surface.surface_mask`, inside
    the PSNR's border) for the targets of Exps. 1 and 2 whose true depth, and their
    inputs', is in ``true_depth``, by the ground-truth cameras ``truth``; none without
    them (a real capture, Exp. 3's parts)."""
    if exp not in (1, 2) or not truth or not true_depth:
        return {}
    config = synthesis_config(config)
    plan = experiment_plan(layout, exp, layout.exp2_cams(config["exp2_sets"]))
    out = {}
    for inputs, targets in plan.values():
        if not all(k in true_depth and k in truth for k in inputs):
            continue
        for t in targets:
            if t in true_depth and t in truth:
                out[t] = surface_mask(t, inputs, truth, true_depth.__getitem__,
                                      int(config["psnr_border_px"]))
    return out


def synthesis_runs(exp: int, cameras: dict[str, dict[str, PinholeCamera]],
                   depths: dict[str, dict[str, np.ndarray]],
                   image_path: Callable[[str, str], str], layout: ArrayLayout, near: float,
                   far: float, config: dict, threads: int = 1,
                   own_depths: Mapping[str, dict[str, np.ndarray]] | None = None
                   ) -> SynthesisRuns:
    """Every run of experiment ``exp`` (:func:`synthesis_job`'s arguments): the scores
    of each (renderer, depth, camera set) and the images kept for the figures."""
    own = dict(own_depths or {})
    config = synthesis_config(config)
    renderers = [config["renderer"]]
    if renderers[0] == "rvs" and config["rvs_compare_dibr"]:
        renderers.append("dibr")
    runs: dict[tuple[str, str, str], dict] = {}
    kept_all: dict[tuple[str, str], np.ndarray] = {}
    images: dict[str, np.ndarray] = {}  # the captured views, read once for every run
    masks = surface_masks(exp, layout, cameras.get("ground_truth"), depths.get("true"),
                          config)
    for renderer in renderers:
        for dname, dmaps in depths.items():
            for cname, cams in cameras.items():
                t0 = time.perf_counter()
                # a camera set's estimated depth made with its own cameras: the estimated
                # maps are the complete calibration's, and no other set is scored on them
                if dname == "estimated" and cname != "complete" and cname not in own:
                    continue
                maps = own[cname] if dname == "estimated" and cname in own else dmaps
                res, kept = run_experiment(exp, cams, image_path, layout, near, far,
                                           {**config, "renderer": renderer,
                                            "threads": int(threads)}, dict(maps), images,
                                           masks)
                runs[(renderer, dname, cname)] = res
                # the time is logged only: the result file stays the same bits
                log.info("%s, %s depth, %s cameras: experiment %d, %.1f s", renderer, dname,
                         cname, exp, time.perf_counter() - t0)
                if dname == "estimated" and renderer == renderers[0]:
                    kept_all.update({(cname, k): img for k, img in kept.items()})
    return SynthesisRuns(exp, tuple(renderers), runs, kept_all)


def synthesis_result(runs: SynthesisRuns, depths: dict[str, dict[str, np.ndarray]],
                     near: float, far: float, config: dict, synth_rel: str = "synth"
                     ) -> tuple[SynthesisResult, dict[str, np.ndarray]]:
    """The result of an experiment's runs (all camera sets: join the parts first,
    :meth:`SynthesisRuns.joined`), as :func:`synthesis_job` returns it; ``depths`` for
    the estimated maps' quality against the true ones."""
    config = synthesis_config(config)
    exp, renderers = runs.experiment, list(runs.renderers)
    border = int(config["psnr_border_px"])
    quality = {}
    if "true" in depths:
        quality = {k: DepthQuality.from_dict(depth_quality(z, depths["true"][k], 0.01, border))
                   for k, z in depths["estimated"].items() if k in depths["true"]}
    setup = SynthesisSetup(near_m=near, far_m=far, psnr_border_px=border,
                           depth_method=config["depth"]["synthesis_method"],
                           depth_quality=quality,
                           # as experiment3 ran it (every run of Exp. 3 has the same)
                           view_stride=next(iter(runs.runs.values()))["view_stride"]
                           if exp == 3 else None)
    files: dict[str, np.ndarray] = {}
    kept_images = []
    for (cname, k), img in sorted(runs.kept.items()):
        # Exp. 3 keeps "<central|lateral>:<shot>/<view>", Exp. 2 the views of a set
        variant, _, view = k.rpartition(":")
        name = f"{cname}_{k.replace('/', '_').replace(':', '_')}.png"
        files[name] = img
        kept_images.append(SynthImage(f"{synth_rel}/{name}", view, cname,
                                      variant or (key_shot(view) if exp == 2 else "")))
    result = SynthesisResult(experiment=exp, renderer=renderers[0],
                             tables=tuple(psnr_tables(exp, runs.runs, renderers, border)),
                             setup=setup, images=tuple(kept_images))
    return result, files


def psnr_tables(exp: int, runs: dict[tuple[str, str, str], dict],
                renderers: list[str], border: int) -> list[PsnrTable]:
    """The PSNR tables of ``runs[(renderer, depth, cameras)]`` (the results of
    :func:`run_experiment`), one per run of the experiment: Exp. 1 one, Exp. 2 one per
    set (``run`` = its shot), Exp. 3 one per input choice (``central``, ``lateral``).
    Ordered by renderer (as given), depth, camera set and run; each target's PSNR
    excludes ``border`` pixels (config ``verify.psnr_border_px``, from its errors per
    ring, :func:`plenocal.verify.scores.psnr_from_rings`)."""
    def parts(res: dict) -> dict[str, dict]:
        if exp == 1:
            return {"": res}
        if exp == 2:
            return res["sets"]
        return {v: res[v] for v in ("central", "lateral")}

    out = []
    for renderer in renderers:
        for depth in DEPTHS:
            for cameras in CAMERA_SETS:
                res = runs.get((renderer, depth, cameras))
                if res is None:
                    continue
                out += [PsnrTable(renderer, depth, cameras, run, tuple(r["inputs"]),
                                  {t: psnr_from_rings(e["sse"], e["shape"], border)
                                   for t, e in r["errors"].items()},
                                  {t: psnr_of_error(*e["surface"])
                                   for t, e in r["errors"].items()
                                   if "surface" in e and e["surface"][1] > 0})
                        for run, r in sorted(parts(res).items())]
    return out
