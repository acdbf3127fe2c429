"""Registration B (Section II-C): the paper's symbols by hand, the exact model against
the thin-lens chief rays, the inverse check of Eqs. 2-3, the two view models' first
order agreement, and rig.json from files; for Keplerian and Galilean MLAs (the kind
from disparity.json), against the traced ground truth of the simulator's optics."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from plenocal import optics as o
from plenocal.artifacts.disparity import Conversion, read_disparity
from plenocal.artifacts.rig import RigB
from plenocal.calib.reg_b import rig
from plenocal.calib.reg_b.datasheet import Datasheet, read_datasheet
from plenocal.calib.reg_b.exact_model import exact_model
from plenocal.calib.reg_b.paper_model import inverse_check, paper_symbols
from plenocal.camera import PinholeCamera
from plenocal.io.files import write_json
from plenocal.verify.rig_truth import compare_with_truth

SIN45 = math.sqrt(0.5)


def datasheet(**kw) -> Datasheet:
    base = dict(pixel_size=0.0055, sensor_width=2048, sensor_height=1536, focus_distance=600.0,
                focal_length_nominal=35.0, mla_pitch=0.13, f_numbers=(2.8,), k=5.0,
                sensor_distance=None, array_step=10.0, near=470.0, far=740.0)
    base.update(kw)
    return Datasheet(**base)


def conversion(**kw) -> Conversion:
    base = dict(d_min=-4.5, d_max=-3.0, q=21.9 * SIN45 / 5, tile=6.0, pitch_px=23.9,
                safe_diameter_px=21.9, width=301, height=225, n_views=5)
    base.update(kw)
    return Conversion(**base)


def test_paper_symbols_by_hand():
    # p = 5.5 um, D = 0.13 mm, F_n 2.8, k = 5, X_o = 600 mm, F_m = 1800 px, T = 6,
    # D_px = 23.9, N = 5, D' = D_px - 2
    s = paper_symbols(datasheet(), conversion(), 1800.0, 5)
    P = 0.0055 * 23.9 / 6  # 0.021908333 mm
    assert s["P"] == pytest.approx(P, rel=1e-12)
    F = 1800 * P  # 39.435 mm
    assert s["F"] == pytest.approx(39.435, rel=1e-12)
    assert s["f"] == pytest.approx(0.364)
    assert s["s"] == pytest.approx(0.455)
    assert s["t"] == pytest.approx(1.82)
    e = F * F / (600 - F)  # 2.7743 mm
    assert s["e"] == pytest.approx(e, rel=1e-12)
    q_px = 21.9 * SIN45 / 5  # 3.09713 px
    assert s["q_px"] == pytest.approx(3.0971277, rel=1e-6)
    assert s["q_paper_px"] == pytest.approx(q_px)
    q = q_px * 0.0055
    assert s["beta"] == pytest.approx(math.atan(q / 0.455), rel=1e-12)
    B = F * q / 0.455  # 1.47636 mm
    assert s["B"] == pytest.approx(1.4763599, rel=1e-6)
    C = (e + 1.82) * q / 0.455
    assert s["C"] == pytest.approx(C, rel=1e-12)
    assert s["alpha"] == pytest.approx(math.atan(C / F), rel=1e-12)
    assert s["X_c"] == pytest.approx(B * F / C, rel=1e-12)  # = F^2 / (e + t) = 338.5 mm
    assert s["X_c"] == pytest.approx(F * F / (e + 1.82), rel=1e-12)
    # Eq. 1 with the paper's sign (nearer = larger disparity)
    assert s["X_n"] == pytest.approx(B * F / (C - 3.0 * P), rel=1e-12)
    assert s["X_f"] == pytest.approx(B * F / (C - 4.5 * P), rel=1e-12)
    assert s["X_n"] < s["X_f"]


def test_middle_f_number_and_given_sensor_distance():
    s = paper_symbols(datasheet(f_numbers=(5.6, 2.8, 4.0), sensor_distance=0.65),
                          conversion(), 1800.0, 5)
    assert s["F_n"] == 4.0
    assert s["f"] == pytest.approx(0.52)
    assert s["s"] == 0.65
    assert s["t"] == pytest.approx(0.65 * 0.52 / (0.65 - 0.52))


def optics(kind: str = "keplerian", focus: float = 0.6) -> o.PlenopticOptics:
    return o.PlenopticOptics(0.035, focus, 130e-6, 2.8, 5.0, 5.5e-6, 2048, 1536, kind=kind)


def true_inputs(opt: o.PlenopticOptics, T: float = 6.0, N: int = 5):
    """Datasheet, conversion and F_m of a camera whose optics are exactly ``opt``;
    the disparity range is the exact one for the scene 470-740 mm (positive for a
    Galilean camera, whose views converge behind the scene)."""
    D_px = opt.micro_image_pitch_px
    F_m = opt.L * T / opt.mla_pitch  # the central view's focal length (see exact_model)
    q_px = (D_px - 2) * SIN45 / N
    ds = datasheet(focus_distance=opt.focus_distance * 1e3)
    L, s = opt.L * 1e3, opt.s * 1e3
    B_e = L * q_px * 0.0055 / s
    Z0 = opt.mla_conjugate_distance * 1e3
    disp = lambda Z: F_m * B_e * (1 / Z - 1 / Z0)  # noqa: E731  (paper sign)
    conv = conversion(q=q_px, tile=T, pitch_px=D_px, safe_diameter_px=D_px - 2,
                      d_min=disp(740.0), d_max=disp(470.0), mla=opt.kind)
    return ds, conv, F_m


# (kind, focus distance m): Keplerian; Galilean converging behind the scene (L > F);
# Galilean focused far, e < |t|, so L < F: the views diverge (Z0 < 0)
KINDS = [("keplerian", 0.6), ("galilean", 0.6), ("galilean", 1.5)]


@pytest.mark.parametrize("kind,focus", KINDS)
def test_exact_model_recovers_the_optics(kind, focus):
    opt = optics(kind, focus)
    ds, conv, F_m = true_inputs(opt)
    sym = paper_symbols(ds, conv, F_m, 5)
    assert sym["s"] == pytest.approx(opt.s * 1e3, rel=1e-12)  # k f / (k -+ 1) by kind
    assert sym["t"] == pytest.approx(opt.t * 1e3, rel=1e-12)  # signed: < 0 Galilean
    ex = exact_model(sym)
    assert ex["L"] == pytest.approx(opt.L * 1e3, rel=1e-12)
    assert ex["F_true"] == pytest.approx(35.0, rel=1e-12)
    assert ex["Z0"] == pytest.approx(opt.mla_conjugate_distance * 1e3, rel=1e-12)
    assert ex["B_paper_over_B"] == pytest.approx((opt.L + opt.s) / opt.L, rel=1e-12)
    # Eq. 1 of the exact model gives back the scene range the disparities came from
    assert ex["X_n"] == pytest.approx(470.0, rel=1e-12)
    assert ex["X_f"] == pytest.approx(740.0, rel=1e-12)
    # Keplerian: converge in front of the scene, disparities negative; Galilean: behind
    # it (positive), or diverge (positive, principal point shifted outwards)
    Z0 = ex["Z0"]
    assert (conv.d_max < 0) == (kind == "keplerian") and conv.d_min * conv.d_max > 0
    assert ex["views"] == ("diverge" if Z0 < 0 else "converge")
    assert {"keplerian": 0 < Z0 < 470, "galilean": Z0 > 740 or Z0 < 0}[kind]
    assert (Z0 < 0) == (focus > 1.0)
    assert np.sign(ex["pp_shift_px"]) == np.sign(Z0) == np.sign(sym["X_c"])


@pytest.mark.parametrize("kind,focus", KINDS)
@pytest.mark.parametrize("hv", [(1, 0), (-2, 1), (2, 2), (0, -1)])
def test_exact_views_reproduce_the_chief_rays(hv, kind, focus):
    """Every tile centre of view (h, v) is sampled along a chief ray of the thin-lens
    model; the exact-model camera must image every point of that ray on that pixel."""
    opt = optics(kind, focus)
    T, N = 6.0, 5
    ds, conv, F_m = true_inputs(opt, T, N)
    doc = rig.build_rig(ds, [conv], F_m, N, model="exact")
    h, v = hv
    name = f"{v + 2}_{h + 2}"
    K, M = RigB(doc).view_poses()[name]
    cam = PinholeCamera(K, M, conv.width, conv.height)
    D_px = conv.pitch_px
    centre = np.array([(opt.width - 1) / 2, (opt.height - 1) / 2])
    ij = np.array([(i, j) for i in range(-30, 31, 5) for j in range(-20, 21, 5)], float)
    lens = centre + ij * D_px
    sensor = lens + np.array([h, v]) * conv.q
    origins, dirs = opt.chief_rays(sensor, lens)
    tile_centres = np.array([(conv.width - 1) / 2, (conv.height - 1) / 2]) + ij * T
    for Z in (0.47, 0.6, 0.74):
        X = origins + dirs * (Z / dirs[:, 2:])
        uv, _ = cam.project(X)
        np.testing.assert_allclose(uv, tile_centres, atol=1e-7)
    # and the centre of projection is where all those rays cross the main lens
    np.testing.assert_allclose(M[:3, 3], origins[0], atol=1e-15)


@pytest.mark.parametrize("kind,focus,paper_alpha", [("keplerian", 0.6, (0.015, 0.03)),
                                                     ("galilean", 0.6, (0.15, 0.3)),
                                                     ("galilean", 1.5, (0.04, 0.07))])
def test_inverse_check_recovers_the_exact_model(kind, focus, paper_alpha):
    opt = optics(kind, focus)
    ds, conv, F_m = true_inputs(opt)
    doc = rig.build_rig(ds, [conv], F_m, 5, model="exact")
    assert doc["mla"] == kind
    ck = doc["exact"]["check"]
    assert ck["verdict"] == "pass"
    assert ck["rel_diff_B"] == pytest.approx(0.0, abs=1e-10)
    assert ck["rel_diff_alpha"] == pytest.approx(0.0, abs=1e-9)
    # the paper's forward B is (L + s) / L too large (~1.2 %, 0.9 % Galilean); its alpha
    # uses F_m P = L + s (in F and in e) where the true focal length belongs: ~2.2 %
    # large for a Keplerian camera, ~22 % for a Galilean one, where e + t = L - F is a
    # small difference (focused at 0.6 m: 0.35 mm against 4.0 mm Keplerian)
    pk = doc["paper"]["check"]
    assert pk["rel_diff_B"] == pytest.approx((opt.L + opt.s) / opt.L - 1, rel=1e-9)
    Fp = opt.L + opt.s
    e_p = Fp ** 2 / (opt.focus_distance - Fp)
    expected = ((e_p + opt.t) / Fp) / ((opt.L - opt.focal_length) / opt.focal_length) - 1
    assert pk["rel_diff_alpha"] == pytest.approx(expected, rel=1e-6)
    assert paper_alpha[0] < pk["rel_diff_alpha"] < paper_alpha[1]
    # in pixels of principal-point shift per step: 0.17 px Keplerian, 0.2 px / 0.13 px
    # Galilean (a large relative difference of a small alpha)
    assert ck["pp_shift_diff_px"] == pytest.approx(0.0, abs=1e-8)
    tan_e = math.tan(doc["exact"]["alpha_equivalent"])
    assert pk["pp_shift_diff_px"] == pytest.approx(
        F_m * (math.tan(doc["paper"]["alpha"]) - tan_e), rel=1e-6)
    assert pk["pp_shift_diff_px"] == pytest.approx(F_m * tan_e * pk["rel_diff_alpha"],
                                                   rel=1e-6)
    assert 0.1 < abs(pk["pp_shift_diff_px"]) < 0.25
    # within the 5 % of the check: of alpha's shift (Keplerian), of the near disparity
    # (Galilean: 6-9 px against a shift of 0.9-2.5 px)
    assert pk["alpha_scale_px"] == pytest.approx(
        max(F_m * abs(tan_e), abs(conv.d_max)), rel=1e-9)
    assert (pk["alpha_scale_px"] > 1.01 * F_m * abs(tan_e)) == (kind == "galilean")
    assert pk["verdict"] == "pass"
    assert doc["check"] is not None and doc["check"]["verdict"] == "pass"


@pytest.mark.parametrize("kind,focus", KINDS)
def test_inverse_check_on_a_measured_disparity_range(kind, focus):
    """The converter measures the range from patch-size percentiles: the near
    disparity 1 % small (as in the tiny Galilean run). The exact model still passes
    (its alpha of a Galilean camera is then 10-20 % off Eq. 3's, 0.1-0.2 px); a wrong
    alpha (its sign flipped: converging for diverging views) or a B 10 % off fails."""
    opt = optics(kind, focus)
    ds, conv, F_m = true_inputs(opt)
    conv = Conversion(**{**conv.__dict__, "d_max": conv.d_max - 0.01 * abs(conv.d_max)})
    sym = paper_symbols(ds, conv, F_m, 5)
    ex = exact_model(sym)
    ck = inverse_check(sym, 470.0, 740.0, ex["B"], ex["alpha_equivalent"])
    assert ck["verdict"] == "pass"
    assert abs(ck["pp_shift_diff_px"]) < 0.25
    if kind == "galilean":
        assert abs(ck["rel_diff_alpha"]) > 0.05  # what the relative test would fail
    for B, alpha in ((ex["B"], -ex["alpha_equivalent"]), (1.1 * ex["B"], ex["alpha_equivalent"])):
        assert inverse_check(sym, 470.0, 740.0, B, alpha)["verdict"] == "fail"


def _pixels(views, X):
    out = {}
    for k, (K, M) in views.items():
        out[k] = PinholeCamera(K, M, 301, 225).project(X)[0]
    return out


def _model_gap(q_scale: float, points: np.ndarray) -> tuple[float, float]:
    """Largest pixel gap between the paper's views (with the exact B and alpha) and the
    exact views over ``points`` (central-view frame, metres); and the exact alpha."""
    opt = optics()
    ds, conv, F_m = true_inputs(opt)
    conv = Conversion(**{**conv.__dict__, "q": conv.q * q_scale})
    sym = paper_symbols(ds, conv, F_m, 5)
    ex = exact_model(sym)
    paper = rig.view_cameras("paper", 5, 301, 225, F_m, ex["B"], alpha=ex["alpha_equivalent"])
    exact = rig.view_cameras("exact", 5, 301, 225, F_m, ex["B"], pp_shift_px=ex["pp_shift_px"])
    a, b = _pixels(paper, points), _pixels(exact, points)
    return max(float(np.abs(a[k] - b[k]).max()) for k in a), ex["alpha_equivalent"]


AXIS = np.stack([np.zeros(4), np.zeros(4), np.linspace(0.47, 0.74, 4)], axis=1)
FIELD = np.mgrid[-0.05:0.05:5j, -0.04:0.04:5j, 0.47:0.74:4j].reshape(3, -1).T


def test_models_agree_to_first_order_in_alpha():
    """Rotating a view by alpha and shifting its principal point by F_m tan(alpha) agree
    to first order in alpha: near the axis (field angle ~ alpha) the gap is third
    order (halving alpha and B divides it by 8); over the field it is
    ~ F_m alpha tan^2(field angle), first order in alpha but small (0.3 px here)."""
    gap1, a1 = _model_gap(1.0, AXIS)
    gap2, a2 = _model_gap(0.5, AXIS)
    assert a2 == pytest.approx(a1 / 2, rel=1e-3)
    assert gap1 < 1e-3  # px, against a principal-point shift of ~7.7 px per step
    assert gap1 / gap2 == pytest.approx(8.0, rel=0.1)
    f1, _ = _model_gap(1.0, FIELD)
    f2, _ = _model_gap(0.5, FIELD)
    assert 0.1 < f1 < 0.5
    assert f1 / f2 == pytest.approx(2.0, rel=0.1)


def test_compare_with_truth_finds_the_paper_errors():
    opt = optics()
    ds, conv, F_m = true_inputs(opt)
    exact = rig.build_rig(ds, [conv], F_m, 5, model="exact")
    truth = {k: PinholeCamera(K, M, 301, 225)
             for k, (K, M) in RigB(exact).view_poses().items()}
    # move the truth into some world frame: the comparison works relative to the centre
    W = np.eye(4)
    W[:3, :3] = o.rotation_matrix(0.2, -0.1)
    W[:3, 3] = (0.3, -0.1, 2.0)
    truth = {k: PinholeCamera(c.K, W @ c.cam_to_world, c.width, c.height)
             for k, c in truth.items()}
    c = compare_with_truth(exact, truth)
    assert abs(c["rel_err_B"]) < 1e-9 and abs(c["rel_err_alpha"]) < 1e-9
    assert c["centre_rmse_mm"] < 1e-9 and c["rotation_max_deg"] < 1e-6
    paper = rig.build_rig(ds, [conv], F_m, 5, model="paper")
    c = compare_with_truth(paper, truth)
    assert c["rel_err_B"] == pytest.approx(paper["exact"]["B_paper_over_B"] - 1, rel=1e-6)
    # the paper's alpha (F = L + s in F and e) is ~2.2 % large
    assert c["rel_err_alpha"] == pytest.approx(paper["exact"]["alpha_paper_over_alpha"] - 1,
                                               rel=5e-3)
    assert c["rotation_max_deg"] > 0.01


def test_compare_with_truth_takes_the_worse_axis():
    """A truth whose views lie 1 % farther apart in x and 1 % nearer in y: the mean of
    the two axes' baselines is the rig's, yet the baseline is 1 % off in each."""
    opt = optics()
    ds, conv, F_m = true_inputs(opt)
    exact = rig.build_rig(ds, [conv], F_m, 5, model="exact")
    truth = {}
    for k, (K, M) in RigB(exact).view_poses().items():
        M = M.copy()
        M[:2, 3] *= (1.01, 0.99)
        truth[k] = PinholeCamera(K, M, 301, 225)
    c = compare_with_truth(exact, truth)
    assert c["rel_err_B_xy"] == pytest.approx([1 / 1.01 - 1, 1 / 0.99 - 1], rel=1e-6)
    assert c["rel_err_B"] == pytest.approx(1 / 0.99 - 1, rel=1e-6)


def test_rig_json_from_files(tmp_path):
    opt = optics()
    ds, conv, F_m = true_inputs(opt)
    cam_yaml = {
        "pixel_size_mm": 0.0055, "sensor_width_px": 2048, "sensor_height_px": 1536,
        "main_lens": {"focus_distance_mm": 600.0, "focal_length_mm": 35.0},
        "mla": {"pitch_mm": 0.13, "f_numbers": [2.8], "k": 5.0},
        "array": {"step_mm": 10.0}, "scene": {"near_mm": 470.0, "far_mm": 740.0},
    }
    (tmp_path / "camera.yaml").write_text(yaml.safe_dump(cam_yaml))
    read = read_datasheet(tmp_path / "camera.yaml")
    assert read == ds
    shots = []
    for i, jitter in enumerate((0.0, 0.05, -0.05)):
        p = tmp_path / f"s{i}.json"
        write_json(p, {"format": "plenocal.disparity", "version": 1, "mla": conv.mla,
                       "D_min": conv.d_min + jitter, "D_max": conv.d_max - jitter,
                       "convention": "paper", "q_px": conv.q, "tile": conv.tile,
                       "D_px": conv.pitch_px, "safe_diameter_px": conv.safe_diameter_px,
                       "width": conv.width, "height": conv.height, "n_views": 5})
        shots.append(read_disparity(p))
    doc = rig.build_rig(read, shots, F_m, 5, model="paper", shot_names=["a", "b", "c"])
    assert doc["symbols"]["D_min_px"] == pytest.approx(conv.d_min)  # median across shots
    assert doc["model"] == "paper" and len(doc["views"]) == 25
    K, M = RigB(doc).view_poses()["2_2"]
    np.testing.assert_allclose(M, np.eye(4))
    np.testing.assert_allclose(K[:2, 2], [150.0, 112.0])
    for model in ("paper", "exact"):  # both models can be rebuilt from the document
        built = rig.build_rig(read, shots, F_m, 5, model=model)
        for k, (K2, M2) in rig.model_views(doc, model).items():
            np.testing.assert_allclose(K2, built["views"][k]["K"], rtol=1e-12)
            np.testing.assert_allclose(M2, built["views"][k]["cam_to_central"], atol=1e-15)
    with pytest.raises(ValueError, match="view size"):
        rig.combine_conversions([conv, Conversion(**{**conv.__dict__, "width": 99})])
    with pytest.raises(FileNotFoundError, match="camera.yaml"):
        read_datasheet(tmp_path / "nope" / "camera.yaml")


def _traced_set(kind: str, focus: float, tmp_path, sensor_distance: bool):
    """A small simulated camera of either MLA kind: the traced ground-truth cameras of
    its 5 x 5 views (plenocal.simulate.groundtruth), its camera.yaml as the simulator writes it
    (with or without mla.sensor_distance_mm) and the disparity.json the converter
    writes for patch sizes of the true scene range 0.47-0.74 m."""
    from plenocal.artifacts.disparity import disparity_record
    from plenocal.config import validate_config
    from plenocal.grid import MicrolensGrid
    from plenocal.simulate.dataset import datasheet as sim_datasheet
    from plenocal.simulate.dataset import make_calib
    from plenocal.simulate.groundtruth import shot_cameras
    from plenocal.simulate.optics_setup import optics_from_config
    from plenocal.viewgeom import make_layout

    root = __import__("pathlib").Path(__file__).resolve().parents[1]
    cfg = validate_config(yaml.safe_load((root / "tests" / "tiny" / "config.yaml").read_text()))
    sim = cfg["datasets"]["tiny"]["simulate"]
    sim["sensor"].update(width=400, height=300)
    sim["mla"]["kind"] = kind
    sim["main_lens"]["focus_distance_m"] = focus
    opt = optics_from_config(sim)
    calib = make_calib(sim, opt)
    grid = MicrolensGrid(calib, opt.width, opt.height)
    layout = make_layout(grid, 5, 6, mla=kind)
    truth, worst = shot_cameras(opt, grid, layout, np.eye(4))
    assert worst < 1e-6
    patch = np.abs([opt.micro_image_disparity_px(z) for z in (0.47, 0.74)])
    doc = disparity_record(layout, calib, patch, np.ones(2, bool), (0.0, 100.0))
    write_json(tmp_path / "disparity.json", doc)
    cam = sim_datasheet(sim, opt)
    if not sensor_distance:
        del cam["mla"]["sensor_distance_mm"]
    (tmp_path / "camera.yaml").write_text(yaml.safe_dump(cam))
    return opt, truth


@pytest.mark.parametrize("kind,focus,sensor_distance", [
    ("keplerian", 0.6, True), ("keplerian", 0.6, False), ("galilean", 0.6, True),
    ("galilean", 0.6, False), ("galilean", 1.5, True)])
def test_registration_b_against_the_traced_truth(kind, focus, sensor_distance, tmp_path):
    """Both MLA kinds end to end from the files registration B reads: the exact model's
    views are the traced ground-truth cameras (baseline, principal-point shift, centres,
    rotations); the paper's views are off by its B and alpha errors, which for a
    Galilean camera are a 0.9 % baseline and a 5-22 % alpha (0.13-0.2 px per step)."""
    opt, truth = _traced_set(kind, focus, tmp_path, sensor_distance)
    conv = read_disparity(tmp_path / "disparity.json")
    assert conv.mla == kind
    # the converter's Galilean disparities are positive in the paper's sign: views
    # converging behind the scene (or diverging); Keplerian ones negative
    assert (conv.d_min > 0) == (kind == "galilean") and conv.d_min * conv.d_max > 0
    ds = read_datasheet(tmp_path / "camera.yaml")
    F_m = truth["2_2"].K[0, 0]
    exact = rig.build_rig(ds, [conv], F_m, 5, model="exact")
    c = compare_with_truth(exact, truth)
    gt = c["truth"]
    # the truth itself: centres L q p / s apart, shift F_m B / Z0 (negative: diverging)
    assert gt["B_m"] == pytest.approx(opt.L * conv.q * opt.pixel_size / opt.s, rel=1e-9)
    assert gt["pp_shift_px"] == pytest.approx(F_m * gt["B_m"] / opt.mla_conjugate_distance,
                                              rel=1e-6)
    assert abs(c["rel_err_B"]) < 1e-6  # the datasheet rounds s to 1e-9 mm
    assert abs(c["err_pp_shift_px"]) < 1e-5
    assert abs(c["rel_err_alpha"]) < 1e-5
    assert c["centre_rmse_mm"] < 1e-6 and c["rotation_max_deg"] < 1e-4  # DLT fit noise
    assert exact["exact"]["X_n"] == pytest.approx(470.0, rel=1e-5)
    assert exact["exact"]["X_f"] == pytest.approx(740.0, rel=1e-5)
    assert exact["exact"]["check"]["verdict"] == "pass"
    paper = rig.build_rig(ds, [conv], F_m, 5, model="paper")
    p = compare_with_truth(paper, truth)
    assert p["rel_err_B"] == pytest.approx(opt.s / opt.L, rel=1e-4)  # B_paper = (L + s) q/s
    assert np.sign(p["estimate"]["pp_shift_px"]) == np.sign(gt["pp_shift_px"])
    lo, hi = {"keplerian": (0.015, 0.03), "galilean": (0.04, 0.3)}[kind]
    assert lo < p["rel_err_alpha"] < hi
    assert 0.1 < abs(p["err_pp_shift_px"]) < 0.25


def test_mla_kind_from_the_converter(tmp_path):
    """disparity.json's ``mla`` decides s from k and the sign of t; a sensor distance on
    the wrong side of f for that kind, an unknown kind or shots of mixed kinds stop
    with the file, the key and the remedy."""
    opt = optics("galilean")
    ds, conv, F_m = true_inputs(opt)
    base = {"format": "plenocal.disparity", "version": 1, "D_px": conv.pitch_px,
            "safe_diameter_px": conv.safe_diameter_px, "q_px": conv.q,
            "tile": conv.tile, "width": conv.width, "height": conv.height, "n_views": 5,
            "D_min": conv.d_min, "D_max": conv.d_max, "convention": "paper"}
    write_json(tmp_path / "g.json", dict(base, mla="galilean"))
    old = {k: v for k, v in base.items() if k not in ("format", "version")}
    write_json(tmp_path / "old.json", old)  # before the format: never guessed at
    write_json(tmp_path / "bad.json", dict(base, mla="plenoptic"))
    g = read_disparity(tmp_path / "g.json")
    assert (g.d_min, g.d_max) == pytest.approx((conv.d_min, conv.d_max)) and g.d_min > 0
    assert g.mla == "galilean"
    with pytest.raises(ValueError, match=r"old\.json: not a disparity.json of version 1"):
        read_disparity(tmp_path / "old.json")
    with pytest.raises(ValueError, match=r"bad\.json: mla = 'plenoptic'.*convert the shot"):
        read_disparity(tmp_path / "bad.json")
    kep = Conversion(**{**conv.__dict__, "mla": "keplerian"})
    with pytest.raises(ValueError, match="shot 1: disparity.json says mla keplerian"):
        rig.combine_conversions([g, kep])
    # s from k: k f / (k + 1) Galilean, k f / (k - 1) Keplerian (f = 0.364 mm)
    assert paper_symbols(ds, g, F_m, 5)["s"] == pytest.approx(0.364 * 5 / 6)
    assert paper_symbols(ds, kep, F_m, 5)["s"] == pytest.approx(0.364 * 5 / 4)
    # a Galilean sensor distance (s < f) read as a Keplerian MLA, and the reverse
    with pytest.raises(ValueError, match="s = 0.3 mm is not above .* keplerian"):
        paper_symbols(datasheet(sensor_distance=0.3), kep, F_m, 5)
    with pytest.raises(ValueError, match="s = 0.455 mm is not below .* galilean"):
        paper_symbols(datasheet(sensor_distance=0.455), g, F_m, 5)
