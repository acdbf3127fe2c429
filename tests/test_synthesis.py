"""The Fig. 6 experiments on a small synthetic array of a textured plane: the exact
cameras give high PSNR, a mis-calibrated view loses dB, layouts match Figs. 7-9."""

import numpy as np
import pytest
from synth.planes import camera_at, fronto_plane, photo_texture, render_plane

from plenocal.artifacts.results import SynthesisResult, SynthesisSetup
from plenocal.camera import PinholeCamera
from plenocal.io.files import to_uint8, write_image
from plenocal.verify import synthesis
from plenocal.verify.experiments import (
    experiment_input_views,
    inner_corner_view,
    layout_from_cams,
)
from plenocal.verify.scores import psnr_from_rings
from plenocal.verify.synthesis import (
    SynthesisContext,
    experiment1,
    experiment2,
    experiment3,
    lateral_view,
    psnr_tables,
    run_experiment,
)
from plenocal.viewgeom import view_names

W, H, F, N = 160, 120, 250.0, 3
COLS, ROWS, STEP, B = 3, 2, 0.01, 0.002
CFG = {"psnr_border_px": 6, "depth_sources_shots": 2, "depth_sources_set": 2,
       "depth": {"lr_check": False, "max_depths": 48, "sgm": {"max_depths": 64}}}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("views")
    plane = fronto_plane(0.6, 0.8, photo_texture(384, noise=0.005), 20.0)
    cams = {}
    for r in range(ROWS):
        for c in range(COLS):
            cam = f"x{c:02d}_y{r:02d}"
            for v in view_names(N):
                vr, vc = map(int, v.split("_"))
                centre = [c * STEP + (vc - 1) * B, r * STEP + (vr - 1) * B, 0.0]
                pc = camera_at(centre, F, W, H)
                cams[f"{cam}/{v}"] = pc
                img, _ = render_plane(pc, plane)
                write_image(root / cam / f"{v}.png", to_uint8(img))
    return root, cams


def _ctx(root, cams):
    layout = layout_from_cams(sorted({k.split("/")[0] for k in cams}), N)
    return SynthesisContext(cams, lambda cam, view: str(root / cam / f"{view}.png"), layout,
                            0.45, 0.8, CFG)


def _psnrs(run: dict, border: int = CFG["psnr_border_px"]) -> dict[str, float]:
    """A run's PSNR per target from its errors per ring (as psnr_tables computes it)."""
    return {t: psnr_from_rings(e["sse"], e["shape"], border) for t, e in run["errors"].items()}


def _mean(run: dict) -> float:
    return float(np.mean(list(_psnrs(run).values())))


def test_experiments_layout_and_psnr(dataset):
    root, cams = dataset
    ctx = _ctx(root, cams)
    shots = sorted({k.split("/")[0] for k in cams})
    e1, kept = experiment1(ctx)
    # every central view but the corners' (the inputs) is a target
    assert set(_psnrs(e1)) == {f"{c}/1_1" for c in shots} - set(e1["inputs"])
    assert len(e1["inputs"]) == 4 and len(_psnrs(e1)) == COLS * ROWS - 4
    assert _mean(e1) > 30.0, _psnrs(e1)
    e2, _ = experiment2(ctx, ["x01_y00"])
    s2 = e2["sets"]["x01_y00"]
    assert set(s2["inputs"]) == {"x01_y00/0_1", "x01_y00/1_0", "x01_y00/1_2", "x01_y00/2_1"}
    assert set(_psnrs(s2)) == {f"x01_y00/{v}" for v in view_names(N)} - set(s2["inputs"])
    assert _mean(s2) > 30.0, _psnrs(s2)
    assert lateral_view(ctx, "x00_y00") == "2_2" and lateral_view(ctx, "x02_y01") == "0_0"
    e3, _ = experiment3(ctx, stride=2)
    # stride 2 on a 3 x 3 set keeps the centre view only
    assert len(_psnrs(e3["central"])) == COLS * ROWS - 4
    assert len(_psnrs(e3["lateral"])) == COLS * ROWS
    assert _mean(e3["lateral"]) > 28.0, _psnrs(e3["lateral"])


def test_runs_do_not_depend_on_the_border(dataset):
    """The renders' errors are kept per ring of pixels, so a run is the same whatever
    verify.psnr_border_px says (only the tables made from it change): rule
    synthesis_exp3_part does not rerun when the border changes."""
    root, cams = dataset
    layout = layout_from_cams(sorted({k.split("/")[0] for k in cams}), N)
    path = lambda c, v: str(root / c / f"{v}.png")  # noqa: E731
    a, _ = run_experiment(1, cams, path, layout, 0.45, 0.8, {**CFG, "psnr_border_px": 0})
    b, _ = run_experiment(1, cams, path, layout, 0.45, 0.8, {**CFG, "psnr_border_px": 20})
    assert a.keys() == b.keys() and a["errors"].keys() == b["errors"].keys()
    for t in a["errors"]:
        np.testing.assert_array_equal(a["errors"][t]["sse"], b["errors"][t]["sse"])
    t0, t20 = (psnr_tables(1, {("dibr", "true", "complete"): a}, ["dibr"], border)[0].psnr_db
               for border in (0, 20))
    assert t0.keys() == t20.keys() and all(t0[t] != t20[t] for t in t0)


def test_bad_calibration_loses_db(dataset):
    root, cams = dataset
    good = _mean(experiment1(_ctx(root, cams))[0])
    bad_cams = dict(cams)
    k = "x00_y00/1_1"
    M = cams[k].cam_to_world.copy()
    M[0, 3] += 0.002  # a corner input off by 2 mm
    bad_cams[k] = PinholeCamera(cams[k].K, M, W, H)
    bad = _mean(experiment1(_ctx(root, bad_cams))[0])
    assert bad < good - 1.0, (good, bad)
    assert np.isfinite(good)


def test_plan_and_shared_depth(dataset):
    """Depth maps given once serve every camera set (the dB lost to calibration with one
    and the same depth); the plan lists what each experiment reads; the means and the dB
    lost derived from the result's PSNR tables are those of the runs."""
    root, cams = dataset
    layout = layout_from_cams(sorted({k.split("/")[0] for k in cams}), N)
    plane = fronto_plane(0.6, 0.8, photo_texture(384, noise=0.005), 20.0)
    keys = experiment_input_views(layout, 1)
    assert keys == [f"{c}/1_1" for c in layout.corners]
    assert experiment_input_views(layout, 3)[4:] == [
        f"{c}/{inner_corner_view(layout, c)}" for c in layout.corners]
    assert [lateral_view(_ctx(root, cams), c) for c in layout.corners] == [
        inner_corner_view(layout, c) for c in layout.corners]
    # Exp. 2 reads the side views of the middle shot's set, or of every shot's
    assert layout.exp2_cams("middle") == [layout.middle_cam]
    assert layout.exp2_cams("all") == layout.cams and len(layout.cams) > 1
    assert experiment_input_views(layout, 2, "all") == [
        f"{c}/{v}" for c in layout.cams for v in layout.side_views()]
    true = {k: render_plane(cams[k], plane)[1] for k in keys}
    bad_cams = dict(cams)
    k = "x01_y00/1_1"  # a target off by 1 mm
    M = cams[k].cam_to_world.copy()
    M[0, 3] += 0.001
    bad_cams[k] = PinholeCamera(cams[k].K, M, W, H)
    runs = {}
    for name, cs in (("complete", bad_cams), ("ground_truth", cams)):
        res, _ = run_experiment(1, cs, lambda c, v: str(root / c / f"{v}.png"), layout, 0.45,
                                0.8, CFG, true)
        runs[("dibr", "true", name)] = runs[("dibr", "estimated", name)] = res
    good, bad = runs[("dibr", "true", "ground_truth")], runs[("dibr", "true", "complete")]
    assert _psnrs(good)["x01_y00/1_1"] > _psnrs(bad)["x01_y00/1_1"] + 3.0
    # the other targets see the same cameras and the same depth: the same PSNR
    assert _psnrs(good)["x01_y01/1_1"] == _psnrs(bad)["x01_y01/1_1"]
    # the figures the report and bench/ derive from the result's PSNR tables
    res = SynthesisResult(experiment=1, renderer="dibr",
                          tables=tuple(psnr_tables(1, runs, ["dibr"], 6)),
                          setup=SynthesisSetup(near_m=0.45, far_m=0.8, psnr_border_px=6,
                                               depth_method="given", depth_quality={}))
    assert res.renderers == ("dibr",)
    lost = res.mean_db_lost("dibr", ("estimated", "complete"), ("estimated", "ground_truth"))
    assert lost == res.mean_db_lost("dibr", ("true", "complete"), ("true", "ground_truth"))
    assert lost[""] > 0.5
    assert lost[""] == pytest.approx(_mean(good) - _mean(bad), abs=1e-12)
    assert res.mean_db_lost("dibr", ("estimated", "complete"), ("true", "complete")) == {"": 0.0}
    for cameras, r in (("complete", bad), ("ground_truth", good)):
        (s,) = res.psnr_stats("dibr", "estimated", cameras).values()
        p = list(_psnrs(r).values())
        assert (s.mean_db, s.min_db, s.max_db, s.count) == pytest.approx(
            (np.mean(p), min(p), max(p), len(p)), abs=1e-12)


def test_each_camera_set_reads_its_own_estimated_depth_where_given(dataset):
    """``own_depths``: the ground-truth cameras' runs with estimated depth read the maps
    made with their own cameras (rule depth_view_truth), the complete calibration's those
    of rule depth_view; the true depth stays one for both. Before, both sets read the
    complete calibration's maps, which fit its geometry and scored the truth on them;
    without maps of its own a set other than the complete calibration has no such run."""
    root, cams = dataset
    layout = layout_from_cams(sorted({k.split("/")[0] for k in cams}), N)
    plane = fronto_plane(0.6, 0.8, photo_texture(384, noise=0.005), 20.0)
    keys = experiment_input_views(layout, 1)
    true = {k: render_plane(cams[k], plane)[1] for k in keys}
    wrong = {k: z * 1.05 for k, z in true.items()}  # depth fitted to other cameras
    path = lambda c, v: str(root / c / f"{v}.png")  # noqa: E731
    sets = {"complete": cams, "ground_truth": cams}
    runs = synthesis.synthesis_runs(1, sets, {"estimated": true, "true": true}, path,
                                    layout, 0.45, 0.8, CFG,
                                    own_depths={"ground_truth": wrong}).runs
    same = runs[("dibr", "true", "ground_truth")]
    assert _psnrs(runs[("dibr", "estimated", "complete")]) == _psnrs(same)
    own = _psnrs(runs[("dibr", "estimated", "ground_truth")])
    assert all(own[t] < p - 1.0 for t, p in _psnrs(same).items()), (own, _psnrs(same))
    # without maps of its own (verify.ground_truth_own_depth off) the ground-truth cameras
    # render with the true depth only: never on the complete calibration's maps
    runs = synthesis.synthesis_runs(1, sets, {"estimated": true, "true": true}, path,
                                    layout, 0.45, 0.8, CFG).runs
    assert set(runs) == {("dibr", "estimated", "complete"), ("dibr", "true", "complete"),
                         ("dibr", "true", "ground_truth")}


def test_threads_render_the_same_images(dataset):
    """The job's cores share the targets (config ``threads``): the same images and PSNR,
    bit for bit, as one thread."""
    root, cams = dataset
    one = _ctx(root, cams)
    two = SynthesisContext(one.cameras, one.image_path, one.layout, one.near, one.far,
                           {**CFG, "threads": 2})
    assert two.workers == 2 and one.workers == 1
    inputs = ["x00_y00/1_1", "x02_y01/1_1"]
    targets = [f"x01_y00/{v}" for v in view_names(N)] + ["x01_y01/1_1"]
    a, b = one.render(inputs, targets), two.render(inputs, targets)
    assert list(a) == list(b) == targets
    for t in targets:
        np.testing.assert_array_equal(a[t], b[t])
    e1, e2 = one.score(inputs, targets)[0], two.score(inputs, targets)[0]
    assert list(e1) == list(e2) == targets
    for t in targets:
        assert e1[t]["shape"] == e2[t]["shape"]
        np.testing.assert_array_equal(e1[t]["sse"], e2[t]["sse"])


def test_scoring_in_chunks_changes_nothing(dataset, monkeypatch):
    """The DIBR's targets are rendered and scored a chunk at a time (memory): any chunk
    size gives the same errors, in the same order, and keeps the same render."""
    root, cams = dataset
    inputs = ["x00_y00/1_1", "x02_y01/1_1"]
    targets = [f"x01_y00/{v}" for v in view_names(N)] + ["x01_y01/1_1"]
    keep = {"x01_y00/1_1"}
    runs = []
    for chunk in (1, 4, len(targets)):
        monkeypatch.setattr(synthesis, "SCORE_CHUNK", chunk)
        runs.append(_ctx(root, cams).score(inputs, targets, keep))
    (e0, k0), *others = runs
    assert list(e0) == targets and list(k0) == ["x01_y00/1_1"]
    for e, k in others:
        assert list(e) == targets
        for t in targets:
            np.testing.assert_array_equal(e[t]["sse"], e0[t]["sse"])
        np.testing.assert_array_equal(k["x01_y00/1_1"], k0["x01_y00/1_1"])


def test_exp3_by_camera_set_joins_to_the_same_result(dataset, tmp_path):
    """Exp. 3 as the workflow runs it - each camera set's runs in a job of its own
    (synthesis_runs, written and read back as plenocal.synthesis_runs), then joined
    (synthesis_result) - gives the result and images of one synthesis_job, file for
    file; parts of another experiment or holding the same run are refused."""
    from plenocal.artifacts.results import (
        read_synthesis_runs,
        write_synthesis,
        write_synthesis_runs,
    )
    from plenocal.verify.synthesis import synthesis_job, synthesis_result, synthesis_runs

    root, cams = dataset
    layout = layout_from_cams(sorted({k.split("/")[0] for k in cams}), N)
    plane = fronto_plane(0.6, 0.8, photo_texture(384, noise=0.005), 20.0)
    keys = experiment_input_views(layout, 3)
    true = {k: render_plane(cams[k], plane)[1] for k in keys}
    depths = {"estimated": {k: z * 1.01 for k, z in true.items()}, "true": true}
    bad = dict(cams)
    M = cams["x01_y00/1_1"].cam_to_world.copy()
    M[0, 3] += 0.001
    bad["x01_y00/1_1"] = PinholeCamera(cams["x01_y00/1_1"].K, M, W, H)
    sets = {"complete": bad, "ground_truth": cams}
    cfg = {**CFG, "exp3_view_stride": 1}

    def path(c, v):
        return str(root / c / f"{v}.png")

    # the ground-truth cameras on maps of their own (verify.ground_truth_own_depth)
    own = {"ground_truth": {k: z * 0.99 for k, z in true.items()}}
    whole, whole_files = synthesis_job(3, sets, depths, path, layout, 0.45, 0.8, cfg,
                                       own_depths=own)
    parts = []
    for name in sets:
        runs = synthesis_runs(3, {name: sets[name]}, depths, path, layout, 0.45, 0.8, cfg,
                              own_depths=own)
        write_synthesis_runs(tmp_path / f"{name}.json", tmp_path / f"{name}.npz", runs)
        parts.append(read_synthesis_runs(tmp_path / f"{name}.json", tmp_path / f"{name}.npz"))
    joined, files = synthesis_result(parts[0].joined(parts[1]), depths, 0.45, 0.8, cfg)
    write_synthesis(tmp_path / "whole.json", whole)
    write_synthesis(tmp_path / "joined.json", joined)
    assert (tmp_path / "whole.json").read_bytes() == (tmp_path / "joined.json").read_bytes()
    assert list(files) == list(whole_files) and len(files) == 2  # lateral, both sets
    for name in files:
        np.testing.assert_array_equal(files[name], whole_files[name])
    assert len(whole.tables) == 2 * 2 * 2  # depths x camera sets x (central, lateral)
    with pytest.raises(ValueError, match="is in two parts"):
        parts[0].joined(parts[0])
    other = synthesis_runs(1, {"complete": bad}, depths, path, layout, 0.45, 0.8, cfg)
    with pytest.raises(ValueError, match="cannot be joined"):
        parts[0].joined(other)
    (tmp_path / "old.json").write_text('{"format": "plenocal.synthesis_runs", "version": 0}')
    with pytest.raises(ValueError, match="not a synthesis runs of version 2"):
        read_synthesis_runs(tmp_path / "old.json", tmp_path / "complete.npz")
