"""Registration A on a synthetic capture: a 3 x 2 parallel array plus 3 rotated
hand-held shots of textured planes (synth.scenes), f = 600 px, 480 x 360."""

import cv2  # noqa: F401  (before pycolmap)
import numpy as np
import pytest
from synth.scenes import default_scene, render, rig_cameras

from plenocal.calib.reg_a.colmap import check_database
from plenocal.calib.reg_a.sfm import (
    RegistrationError,
    check_models,
    check_shots,
    features_a,
    map_a,
    match_a,
)
from plenocal.calib.reg_a.uncertainty import focal_std_px
from plenocal.camera import rotation_angle_deg, umeyama
from plenocal.io.files import dumps_json, write_image, write_json
from plenocal.report.sources import WARNING_SOURCES

F, W, H, STEP = 600.0, 480, 360, 0.03


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("sfm")
    cams = rig_cameras(f=F, width=W, height=H, step_m=STEP, handheld=3)
    scene = default_scene()
    views = {}
    for name, cam in cams.items():
        views[name] = root / "views" / name / "2_2.png"
        write_image(views[name], render(cam, scene))
    return root, cams, views


@pytest.fixture(scope="module")
def registered(capture):
    root, cams, views = capture
    ra = root / "reg_a"
    features_a(views, ra / "images", ra / "database.db")
    match_a(ra / "database.db")
    doc = map_a(ra / "database.db", ra / "images", ra / "model").to_dict()
    return ra, doc


def _align(doc, cams):
    names = sorted(cams)
    src = np.array([np.asarray(doc["cameras"][n]["cam_to_world"])[:3, 3] for n in names])
    dst = np.array([cams[n].centre for n in names])
    s, R, t = umeyama(src, dst)
    rmse = np.sqrt(((dst - (s * src @ R.T + t)) ** 2).sum(axis=1).mean())
    rot = max(rotation_angle_deg(R @ np.asarray(doc["cameras"][n]["cam_to_world"])[:3, :3],
                                 cams[n].R) for n in names)
    return rmse, rot


def test_registration_a_recovers_focal_and_poses(capture, registered):
    _, cams, _ = capture
    ra, doc = registered
    assert sorted(doc["cameras"]) == sorted(cams)
    assert doc["units"] == "sfm" and doc["width"] == W and doc["height"] == H
    assert abs(doc["focal_px"] / F - 1) < 0.01
    K = np.asarray(doc["cameras"]["hand00"]["K"])
    # internal convention: principal point at ((W-1)/2, (H-1)/2), not COLMAP's W/2
    np.testing.assert_allclose(K[:2, 2], [(W - 1) / 2, (H - 1) / 2], atol=1e-9)
    rmse, rot = _align(doc, cams)
    assert rmse < 0.02 * STEP
    assert rot < 0.2
    assert doc["mean_reprojection_error_px"] < 0.5
    assert (ra / "model" / "images.bin").is_file()


def test_registration_a_says_how_firmly_its_focal_length_is_fixed(registered):
    """reg_a.json's focal_std_px is the covariance's figure of the model it wrote (the
    report shows it on real captures), and the focal length is within a few of it."""
    ra, doc = registered
    std = doc["focal_std_px"]
    assert std == pytest.approx(focal_std_px(ra / "model"), rel=1e-9)  # the model read back
    assert 0 < std < 0.05 * doc["focal_px"]
    assert abs(doc["focal_px"] - F) < 4 * std


def test_registration_a_is_deterministic(capture, registered, tmp_path):
    _, _, views = capture
    ra, doc = registered
    features_a(views, tmp_path / "images", tmp_path / "database.db")
    match_a(tmp_path / "database.db")
    again = map_a(tmp_path / "database.db", tmp_path / "images", tmp_path / "model").to_dict()
    assert dumps_json(again) == dumps_json(doc)
    assert (tmp_path / "model" / "points3D.bin").read_bytes() == \
        (ra / "model" / "points3D.bin").read_bytes()


def test_map_a_leaves_its_input_database_untouched(capture, registered, tmp_path):
    """Issue 34: map_a opened reg_a/database.db with pycolmap, which rewrites its SQLite
    header (the change counter) on every open: a rule must not modify its inputs."""
    ra, _ = registered
    db = tmp_path / "database.db"
    db.write_bytes((ra / "database.db").read_bytes())
    before = db.read_bytes()
    map_a(db, ra / "images", tmp_path / "model")
    assert db.read_bytes() == before


def test_a_damaged_database_is_named_with_its_remedy(capture, registered, tmp_path):
    """A features or matches database cut short gave pycolmap's "No registered database
    factory succeeded", naming neither the file nor the remedy, and rule match_a left its
    copy (database.db.part) behind."""
    ra, _ = registered
    good = (ra / "database.db").read_bytes()
    db = tmp_path / "features.db"
    db.write_bytes(good)
    assert check_database(db, "run features_a") == len(capture[1])
    assert db.read_bytes() == good  # opened read-only: not even its change counter moves
    assert sorted(p.name for p in tmp_path.iterdir()) == ["features.db"]  # no -wal, -shm
    # writes not folded in (a COLMAP still writing, or killed): the immutable open would
    # read the main file alone
    (tmp_path / "features.db-wal").write_bytes(b"\0" * 64)
    with pytest.raises(ValueError, match=rf"{db}: holds writes not yet folded in "
                                         r"\(features\.db-wal beside it.*\); run features_a"):
        check_database(db, "run features_a")
    (tmp_path / "features.db-wal").unlink()
    for damaged in (good[: len(good) // 3], b"", b"SQLite format 3\0" + bytes(200)):
        db.write_bytes(damaged)
        with pytest.raises(ValueError, match=rf"{db}: (not a readable|a damaged) COLMAP "
                                             r"database \(.*\); run features_a"):
            check_database(db, "run features_a")
    with pytest.raises(FileNotFoundError, match="COLMAP database not found; run it"):
        check_database(tmp_path / "missing.db", "run it")


def test_global_mapper(capture, registered, tmp_path):
    _, cams, _ = capture
    ra, _ = registered
    doc = map_a(ra / "database.db", ra / "images", tmp_path / "model", mapper="global").to_dict()
    assert doc["mapper"] == "global" and sorted(doc["cameras"]) == sorted(cams)
    assert abs(doc["focal_px"] / F - 1) < 0.01
    rmse, rot = _align(doc, cams)
    assert rmse < 0.02 * STEP


def test_unregistered_view_is_named(capture, tmp_path):
    _, _, views = capture
    rng = np.random.default_rng(0)
    blank = tmp_path / "views" / "hand07" / "2_2.png"
    # a view of some other scene: features, but no match with the rest
    write_image(blank, cv2.GaussianBlur(rng.integers(0, 255, (H, W, 3), dtype=np.uint8),
                                        (0, 0), 2))
    v = dict(views, hand07=blank)
    features_a(v, tmp_path / "images", tmp_path / "database.db")
    match_a(tmp_path / "database.db")
    with pytest.raises(RegistrationError, match=r"did not register hand07;.*hand-held"):
        map_a(tmp_path / "database.db", tmp_path / "images", tmp_path / "model")


class _Model:
    """A reconstruction as check_models reads one: its registered images' names."""

    def __init__(self, names):
        self.names = list(names)

    def num_reg_images(self):
        return len(self.names)

    def reg_image_ids(self):
        return list(range(len(self.names)))

    def image(self, j):
        return type("Image", (), {"name": self.names[j]})()


def test_a_split_registration_names_the_shots_in_no_model():
    """The split's error listed each model's shots but not those in none of them."""
    names = [f"{c}.png" for c in ("hand00", "hand01", "hand02", "x00_y00", "x01_y00")]
    recs = {0: _Model(["x00_y00.png", "x01_y00.png"]), 1: _Model(["hand00.png"])}
    with pytest.raises(RegistrationError, match=r"split the scene into 2 models \(model 0: "
                                                r"x00_y00, x01_y00; model 1: hand00; in none: "
                                                r"hand01, hand02\); try:"):
        check_models(recs, names, "incremental")


def test_array_alone_is_refused():
    with pytest.raises(RegistrationError, match="focal length is undetermined"):
        check_shots(["x00_y00", "x01_y00", "x02_y00"])


def test_views_of_different_sizes_are_refused(capture, tmp_path):
    _, _, views = capture
    small = tmp_path / "hand05.png"
    write_image(small, np.zeros((H // 2, W // 2, 3), np.uint8))
    with pytest.raises(RegistrationError, match="differ in size"):
        features_a(dict(views, hand05=small), tmp_path / "images", tmp_path / "db.db")


def test_model_folder_is_readable_and_stale_temps_are_removed(capture, registered, tmp_path):
    """The COLMAP model folder gets the umask's permissions (not mkdtemp's 0700: other
    users of a shared cluster read it), and a killed map_a's temporary folders are
    removed by the next run instead of staying behind for ever."""
    import os
    import stat

    ra, _ = registered
    old = os.umask(0o022)
    try:
        out = tmp_path / "reg_a"
        out.mkdir()
        stale = [out / ".map_a.dead1.tmpdir", out / ".model.dead3.tmpdir"]
        for p in stale:
            (p / "sub").mkdir(parents=True)
        keep = out / ".model.json.x.part"  # another writer's file temp: not a folder temp
        keep.write_text("x")
        db = out / "database.db"
        db.write_bytes((ra / "database.db").read_bytes())
        doc = map_a(db, ra / "images", out / "model").to_dict()
    finally:
        os.umask(old)
    assert len(doc["cameras"]) == len(list((ra / "images").glob("*.png")))
    mode = stat.S_IMODE((out / "model").stat().st_mode)
    assert mode == 0o755, oct(mode)
    assert not any(p.exists() for p in stale), sorted(p.name for p in out.iterdir())
    assert keep.exists()
    assert sorted(p.name for p in out.iterdir()) == [".model.json.x.part", "database.db",
                                                    "model"]


def test_few_features_warning_is_in_the_output(tmp_path):
    """A texture-poor central view is named in features.json's warnings (which the
    report shows), not only in the job's log."""
    rng = np.random.default_rng(0)
    views = {}
    for k, name in enumerate(["x00_y00", "x01_y00", "x02_y00", "hand00"]):
        img = np.full((H, W, 3), 128, np.uint8)
        if name != "hand00":  # the hand-held shot sees a blank wall
            img = cv2.GaussianBlur(rng.integers(0, 255, (H, W, 3), dtype=np.uint8), (5, 5),
                                   1.5 + 0.1 * k)
        views[name] = tmp_path / "views" / name / "1_1.png"
        write_image(views[name], img)
    info = features_a(views, tmp_path / "images", tmp_path / "features.db")
    assert len(info["warnings"]) == 1, info["warnings"]
    assert "hand00 (" in info["warnings"][0] and "x00_y00" not in info["warnings"][0]
    # written as rule features_a writes it, read as the report reads it: the same messages
    write_json(tmp_path / "features.json", info)
    read = dict(WARNING_SOURCES)["reg_a/features.json"]
    assert read(tmp_path / "features.json") == tuple(info["warnings"])


def test_a_shot_held_by_few_points_is_a_warning_the_report_reads(tmp_path):
    """tele-s36's hand03 was held by 19 points against a median of 1,221, and was 8.5 mm
    off; the weakest shot of every other kept capture had a third of its median or more."""
    from plenocal.artifacts.reg_a import RegistrationA, read_reg_a, write_reg_a  # noqa: PLC0415
    from plenocal.calib.reg_a.sfm import WEAK_SHOT_SHARE, weak_shots  # noqa: PLC0415
    from plenocal.camera import PinholeCamera  # noqa: PLC0415

    points = {"x00_y00": 1221, "x01_y00": 1300, "hand00": 974, "hand03": 19}
    (msg,) = weak_shots(points)
    assert "shot hand03 by 19 points" in msg and "median of 1098" in msg  # (974 + 1221) / 2
    assert weak_shots({**points, "hand03": 434}) == []  # tele-s34's weakest: a third
    assert weak_shots({"a": 100, "b": int(100 * WEAK_SHOT_SHARE)}) == []
    cam = PinholeCamera(np.diag([500.0, 500.0, 1.0]), np.eye(4), 64, 48)
    reg = RegistrationA(500.0, 64, 48, "incremental", {"hand03": cam},
                        stats={"points_per_shot": points, "warnings": [msg]})
    write_reg_a(tmp_path / "reg_a.json", reg)
    assert read_reg_a(tmp_path / "reg_a.json").stats["warnings"] == [msg]
    assert dict(WARNING_SOURCES)["reg_a/reg_a.json"](tmp_path / "reg_a.json") == (msg,)


def test_a_mapper_that_builds_no_model_gives_way_to_the_other(registered, tmp_path,
                                                              monkeypatch):
    """COLMAP's global mapper built no model from a held-out capture's 21 views (tele-s39:
    its bundle adjustment left no 3-D point); the incremental one registers them. map_a
    tries the other mapper once, uses it, and says so in reg_a.json's warnings."""
    from plenocal.calib.reg_a import sfm  # noqa: PLC0415

    ra, _ = registered
    real = sfm.run_mapper

    def global_fails(database, image_dir, *, mapper, **kw):
        return {} if mapper == "global" else real(database, image_dir, mapper=mapper, **kw)

    monkeypatch.setattr(sfm, "run_mapper", global_fails)
    doc = map_a(ra / "database.db", ra / "images", tmp_path / "model",
                mapper="global").to_dict()
    assert doc["mapper"] == "incremental"
    (note, *_) = doc["warnings"]
    assert note.startswith("registration A: the global mapper (sfm.mapper) failed "
                           "(registration A (global) built no model from")
    assert note.endswith("the incremental mapper registered every view and is used")
    # neither mapper: the first one's error, and the second's after it
    monkeypatch.setattr(sfm, "run_mapper", lambda *a, **kw: {})
    with pytest.raises(RegistrationError, match=r"^registration A \(global\) built no "
                       r"model .* \(sfm.mapper incremental, tried next, failed too: "):
        map_a(ra / "database.db", ra / "images", tmp_path / "model2", mapper="global")
