"""Exports: a 3-D point projected through each export, parsed back independently,
lands on the same pixel as through the internal PinholeCamera (within 1e-6 px); the
16-bit normalised-disparity depth maps."""

from __future__ import annotations

import json
import math

import cv2  # (before pycolmap, see DESIGN.md)
import numpy as np
import pytest

from plenocal import optics as o
from plenocal.artifacts.cameras import read_camera_units, read_cameras, write_cameras
from plenocal.camera import PinholeCamera, intrinsics
from plenocal.export import colmap_model, depthmaps, mpeg


def cameras() -> dict[str, PinholeCamera]:
    rng = np.random.default_rng(3)
    out = {}
    for i, cam in enumerate(["x00_y00", "hand01"]):
        R_A = o.rotation_matrix(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3))
        c, s = math.cos(0.4 * i - 0.1), math.sin(0.4 * i - 0.1)
        R_A = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ R_A
        for view, (h, v) in {"2_2": (0, 0), "0_4": (2, -2), "3_1": (-1, 1)}.items():
            M = np.eye(4)
            M[:3, :3] = R_A @ o.rotation_matrix(h * 0.004, v * 0.004)
            M[:3, 3] = rng.normal(size=3) * 0.05 + R_A @ np.array([h, v, 0.0]) * 0.0015
            K = intrinsics(1800.0 + i, 150.0 + 7.7 * h, 112.0 + 7.7 * v)
            out[f"{cam}/{view}"] = PinholeCamera(K, M, 301, 225)
    return out


def points(cam: PinholeCamera) -> np.ndarray:
    """World points in front of a camera, spread over its image."""
    uv = np.array([[3.0, 5.0], [150.0, 112.0], [290.5, 220.25], [40.0, 200.0]])
    z = np.array([0.47, 0.6, 0.74, 0.55])
    return cam.unproject(uv, z)


# -- independent parsers --------------------------------------------------------------


def _rot(axis: int, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i] = R[j, j] = c
    R[i, j], R[j, i] = -s, s
    return R


def tmiv_project(entry: dict, X_cv: np.ndarray) -> np.ndarray:
    """TMIV's perspective projection, from the JSON fields alone. The world is the
    project's world expressed in OMAF axes (x fwd = z_cv, y left = -x_cv, z up = -y_cv)."""
    Xw = np.stack([X_cv[:, 2], -X_cv[:, 0], -X_cv[:, 1]], axis=1)
    yaw, pitch, roll = np.radians(entry["Rotation"])
    R = _rot(2, yaw) @ _rot(1, pitch) @ _rot(0, roll)  # q_yaw q_pitch q_roll
    p = (Xw - np.asarray(entry["Position"])) @ R  # R^T (X - C) row-wise
    fx, fy = entry["Focal"]
    cx, cy = entry["Principle_point"]
    u = -fx * p[:, 1] / p[:, 0] + cx - 0.5  # TMIV pixel (0,0) spans [0, 1)
    v = -fy * p[:, 2] / p[:, 0] + cy - 0.5
    return np.stack([u, v], axis=1)


def test_mpeg_json_round_trip(tmp_path):
    cams = cameras()
    mpeg.write_mpeg(tmp_path / "cameras.json", cams, (0.42, 0.81), content_name="test")
    doc = json.loads((tmp_path / "cameras.json").read_text())
    assert doc["Version"] == "4.0" and doc["lengthsInMeters"] is True
    entries = {e["Name"]: e for e in doc["cameras"]}
    assert sorted(entries) == sorted(k.replace("/", "_") for k in cams)
    assert doc["sourceCameraNames"] == sorted(entries)
    for key, cam in cams.items():
        e = entries[key.replace("/", "_")]
        assert e["Projection"] == "Perspective" and e["Resolution"] == [301, 225]
        assert e["Depth_range"] == [0.42, 0.81] and e["BitDepthDepth"] == 16
        assert e["ColorSpace"] == "YUV420" and e["DepthColorSpace"] == "YUV420"
        X = points(cam)
        uv, _ = cam.project(X)
        np.testing.assert_allclose(tmiv_project(e, X), uv, atol=1e-6)


def test_omaf_axes_and_euler_angles():
    # a camera looking along world +x_cv (OpenCV) looks to the OMAF right: yaw -90 deg
    M = np.eye(4)
    M[:3, :3] = o.rotation_matrix(-math.pi / 2, 0.0)  # optical axis -> +x
    assert (M[:3, :3] @ [0, 0, 1]) == pytest.approx([1, 0, 0], abs=1e-12)
    pos, rot = mpeg.omaf_pose(M)
    assert rot == pytest.approx([-90.0, 0.0, 0.0], abs=1e-9)
    # identity: looking forward, no rotation
    pos, rot = mpeg.omaf_pose(np.eye(4))
    assert rot == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    # looking up (optical axis towards -y_cv): in TMIV's R = Rz Ry Rx a positive pitch
    # (about y left) turns x forward towards -z (down), so looking up is pitch < 0
    M = np.eye(4)
    M[:3, :3] = o.rotation_matrix(0.0, 0.2)  # about x_cv
    assert (M[:3, :3] @ [0, 0, 1])[1] < 0
    _, rot = mpeg.omaf_pose(M)
    assert rot == pytest.approx([0.0, -math.degrees(0.2), 0.0], abs=1e-9)
    for ypr in ([10.0, -20.0, 30.0], [-170.0, 80.0, -5.0]):
        assert mpeg.matrix_to_ypr(mpeg.ypr_to_matrix(*ypr)) == pytest.approx(ypr, abs=1e-9)
    # a view a micro-degree from straight up: the matrix read back exactly (the arcsine
    # lost 2.5e-9 there), yaw and roll then traded along the axis they share
    for pitch in (90.0 - 1e-6, -(90.0 - 1e-5)):
        R = mpeg.ypr_to_matrix(20.0, pitch, 10.0)
        assert np.abs(mpeg.ypr_to_matrix(*mpeg.matrix_to_ypr(R)) - R).max() < 1e-14


def test_colmap_model_round_trip(tmp_path):
    import pycolmap  # noqa: PLC0415

    cams = cameras()
    colmap_model.write_colmap(tmp_path / "colmap", cams)
    for f in ("cameras.bin", "images.bin", "points3D.bin"):
        assert (tmp_path / "colmap" / f).is_file()
    rec = pycolmap.Reconstruction(str(tmp_path / "colmap"))
    assert rec.num_images() == len(cams) and rec.num_reg_images() == len(cams)
    # shared intrinsics are shared cameras: hand01 and x00_y00 differ in focal
    assert rec.num_cameras() == 6
    by_name = {im.name: im for im in rec.images.values()}
    for key, cam in cams.items():
        im = by_name[f"{key}.png"]
        c = rec.cameras[im.camera_id]
        assert str(c.model).endswith("PINHOLE") and (c.width, c.height) == (301, 225)
        fx, fy, cx, cy = c.params
        T = np.asarray(im.cam_from_world().matrix())
        X = points(cam)
        Xc = X @ T[:, :3].T + T[:, 3]
        uv_colmap = np.stack([fx * Xc[:, 0] / Xc[:, 2] + cx, fy * Xc[:, 1] / Xc[:, 2] + cy], 1)
        uv, _ = cam.project(X)
        np.testing.assert_allclose(uv_colmap - 0.5, uv, atol=1e-6)


def test_plain_round_trip(tmp_path):
    cams = cameras()
    write_cameras(tmp_path / "cameras.json", cams, extra={"source": "test"})
    doc = json.loads((tmp_path / "cameras.json").read_text())
    assert doc["units"] == "m" and doc["source"] == "test"
    assert (doc["format"], doc["version"]) == ("plenocal.cameras", 1)
    back = read_cameras(tmp_path / "cameras.json")
    assert read_camera_units(tmp_path / "cameras.json") == "m"
    for key, cam in cams.items():
        X = points(cam)
        np.testing.assert_allclose(back[key].project(X)[0], cam.project(X)[0], atol=1e-6)
    with pytest.raises(ValueError, match="view key"):
        write_cameras(tmp_path / "x.json", {"nokey": cams["hand01/2_2"]})
    with pytest.raises(ValueError, match="units"):
        write_cameras(tmp_path / "x.json", cams, units="mm")
    with pytest.raises(ValueError, match="overwrite"):
        write_cameras(tmp_path / "x.json", cams, extra={"units": "sfm"})


def test_camera_file_of_another_version_or_shape_is_refused(tmp_path):
    """DESIGN.md's layout without the format (an older file), another version, an unknown
    unit or a camera without its K: each an error naming the file and the remedy."""
    cams = cameras()
    path = tmp_path / "cameras.json"
    write_cameras(path, cams)
    doc = json.loads(path.read_text())
    for change, match in ((lambda d: d.pop("format"), "version 1"),
                          (lambda d: d.update(version=2), "version 1"),
                          (lambda d: d.update(units="mm"), "units 'mm'"),
                          (lambda d: d["cameras"]["hand01/2_2"].pop("K"),
                           "camera 'hand01/2_2'.*without key.*'K'"),
                          # each of these was a bare TypeError / ValueError / AttributeError
                          # without the file, or was read without a word (a review's finding)
                          (lambda d: d["cameras"]["hand01/2_2"]["K"][0].__setitem__(0, "abc"),
                           "camera 'hand01/2_2'.*'abc'"),
                          (lambda d: d["cameras"]["hand01/2_2"].update(width=None),
                           "camera 'hand01/2_2'.*width None: a whole number"),
                          (lambda d: d["cameras"]["hand01/2_2"].update(width=310.7),
                           "width 310.7: a whole number"),
                          (lambda d: d.update(cameras=[1]), "'cameras' holds a list"),
                          (lambda d: d.update(cameras={}), "'cameras' holds an empty mapping"),
                          (lambda d: d["cameras"].update(badname=d["cameras"]["hand01/2_2"]),
                           "camera 'badname'.*not a view key")):
        bad = json.loads(json.dumps(doc))
        change(bad)
        p = tmp_path / "bad.json"
        p.write_text(json.dumps(bad))
        with pytest.raises(ValueError, match=match) as err:
            read_cameras(p)
        assert str(p) in str(err.value) and "rerun" in str(err.value)
    with pytest.raises(FileNotFoundError, match="cameras.json"):
        read_cameras(tmp_path / "missing" / "cameras.json")


def _broken(cam: PinholeCamera, what: str) -> PinholeCamera:
    """``cam`` with one defect that no export may write."""
    K, M = cam.K.copy(), cam.cam_to_world.copy()
    if what == "reflection":
        M[:3, 0] *= -1.0  # a flipped axis: orthonormal, determinant -1
    elif what == "scaled":
        M[:3, :3] *= 1.001
    elif what == "nan":
        M[0, 3] = np.nan
    elif what == "focal":
        K[0, 0] = -K[0, 0]
    elif what == "skew":
        K[0, 1] = 0.5
    return PinholeCamera(K, M, cam.width, cam.height)


@pytest.mark.parametrize("what, match", [("reflection", "determinant -1"),
                                         ("scaled", "not orthonormal"), ("nan", "NaN"),
                                         ("focal", "positive")])
def test_writers_refuse_a_camera_that_is_no_pinhole(tmp_path, what, match):
    """A reflection (a flipped axis), a scaled rotation, a NaN or a negative focal length
    reaches no export: each writer names the target, the camera and the defect, and writes
    nothing; the plain file's reader refuses it too (a file edited by hand)."""
    cams = cameras()
    cams["hand01/3_1"] = _broken(cams["hand01/3_1"], what)
    for write, target in ((lambda p: write_cameras(p, cams), tmp_path / "cameras.json"),
                          (lambda p: mpeg.write_mpeg(p, cams, (0.3, 2.0)), tmp_path / "m.json"),
                          (lambda p: colmap_model.write_colmap(p, cams), tmp_path / "colmap")):
        with pytest.raises(ValueError, match=match) as err:
            write(target)
        assert "'hand01/3_1'" in str(err.value) and "nothing was written" in str(err.value)
        assert not target.exists()
    good = tmp_path / "good.json"
    write_cameras(good, cameras())
    doc = json.loads(good.read_text())
    bad = _broken(cameras()["hand01/3_1"], what)
    doc["cameras"]["hand01/3_1"] = {"K": bad.K.tolist(),
                                     "cam_to_world": bad.cam_to_world.tolist(),
                                     "width": 301, "height": 225}
    good.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=match) as err:
        read_cameras(good)
    assert str(good) in str(err.value) and "rerun" in str(err.value)


def test_skew_is_kept_in_the_plain_file_and_refused_by_the_exports(tmp_path):
    """The plain camera file holds a whole K (a fitted ground-truth camera may carry skew);
    COLMAP's PINHOLE and MPEG's cameras have no skew term, so their writers refuse it."""
    cams = cameras()
    cams["x00_y00/2_2"] = _broken(cams["x00_y00/2_2"], "skew")
    write_cameras(tmp_path / "cameras.json", cams)
    assert read_cameras(tmp_path / "cameras.json")["x00_y00/2_2"].K[0, 1] == 0.5
    with pytest.raises(ValueError, match="skew"):
        mpeg.write_mpeg(tmp_path / "m.json", cams, (0.3, 2.0))
    with pytest.raises(ValueError, match="skew"):
        colmap_model.write_colmap(tmp_path / "colmap", cams)


def test_depth16():
    near, far = 0.4, 0.8
    z = np.array([[0.4, 0.8, 0.0, 0.5333333333333333], [np.nan, 0.3, 2.0, 0.6]])
    L = depthmaps.depth16(z, near, far)
    assert L.dtype == np.uint16
    assert L[0, 0] == 65535  # near
    assert L[0, 1] == 1  # far: level 0 is reserved for invalid
    assert L[0, 2] == 0 and L[1, 0] == 0  # invalid
    assert L[0, 3] == round(65535 * (1 / 0.5333333333333333 - 1.25) / (2.5 - 1.25))  # 32768
    assert L[1, 1] == 65535 and L[1, 2] == 1  # clipped
    expected = round(65535 * (1 / 0.6 - 1 / far) / (1 / near - 1 / far))
    assert L[1, 3] == expected
    back = depthmaps.depth_from16(L, near, far)
    assert back[1, 3] == pytest.approx(0.6, rel=1e-4)
    assert back[0, 2] == 0.0
    with pytest.raises(ValueError):
        depthmaps.depth16(z, 0.8, 0.4)


def test_depth16_files(tmp_path):
    from plenocal.io.files import read_image  # noqa: PLC0415

    z = np.full((5, 7), 0.6)
    z[0, 0] = 0
    depthmaps.write_depth16_png(tmp_path / "d.png", z, 0.4, 0.8)
    img = read_image(tmp_path / "d.png")
    assert img.dtype == np.uint16 and img[0, 0] == 0 and img[1, 1] == depthmaps.depth16(
        np.array(0.6), 0.4, 0.8)
    depthmaps.write_depth16_yuv(tmp_path / "d.yuv", z, 0.4, 0.8)
    raw = np.frombuffer((tmp_path / "d.yuv").read_bytes(), dtype="<u2")
    assert raw.size == 5 * 7 + 2 * 2 * 3  # chroma W // 2 x H // 2, as RVS reads it
    np.testing.assert_array_equal(raw[:35].reshape(5, 7), img)


def test_texture_yuv420_layout_and_chroma_by_hand():
    """Four distinct pixels per 2 x 2 block: Y in row order, one pixel each; U and V the
    rounded mean of each block's four (not any one of them); an odd last column and row
    dropped from the chroma planes."""
    rgb = np.array([[[255, 0, 0], [0, 0, 255], [10, 20, 30], [200, 100, 50], [7, 7, 7]],
                    [[0, 255, 0], [255, 255, 0], [90, 80, 70], [0, 0, 0], [9, 9, 9]],
                    [[1, 2, 3], [4, 5, 6], [7, 8, 9], [10, 11, 12], [13, 14, 15]]],
                   np.uint8)  # 5 x 3: chroma of the two 2 x 2 blocks of rows 0-1
    raw = depthmaps.texture_yuv420(rgb)
    assert len(raw) == 15 + 2 + 2
    yuv = {(r, c): cv2.cvtColor(rgb[r:r + 1, c:c + 1], cv2.COLOR_RGB2YUV)[0, 0].astype(float)
           for r in range(3) for c in range(5)}
    assert list(raw[:15]) == [int(round(yuv[r, c][0])) for r in range(3) for c in range(5)]
    for plane, channel in ((raw[15:17], 1), (raw[17:19], 2)):
        for block, got in enumerate(plane):
            four = [yuv[r, 2 * block + c][channel] for r in (0, 1) for c in (0, 1)]
            assert got == int(np.rint(sum(four) / 4))
            # the four differ by more than rounding: no one pixel's value passes for the mean
            assert all(abs(got - x) > 1 for x in four)


@pytest.mark.parametrize("size", [(6, 4), (7, 5)])
def test_texture_yuv420(tmp_path, size):
    w, h = size
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    rgb[:, :] = rgb[:1, :1]  # flat colour: 4:2:0 loses nothing
    depthmaps.write_texture_yuv(tmp_path / "t.yuv", rgb)
    raw = np.frombuffer((tmp_path / "t.yuv").read_bytes(), dtype=np.uint8)
    assert raw.size == w * h + 2 * (w // 2) * (h // 2)
    y = raw[: w * h].reshape(h, w)
    u = raw[w * h: w * h + (w // 2) * (h // 2)]
    v = raw[w * h + (w // 2) * (h // 2):]
    yuv = np.dstack([y[: 2 * (h // 2): 2, : 2 * (w // 2): 2].astype(np.uint8),
                     u.reshape(h // 2, w // 2), v.reshape(h // 2, w // 2)])
    back = cv2.cvtColor(yuv, cv2.COLOR_YUV2RGB)  # what RVS does with it
    assert np.abs(back.astype(int) - rgb[: 2 * (h // 2): 2, : 2 * (w // 2): 2]).max() <= 2


@pytest.mark.parametrize("far", [math.inf, 1000.0, 2000.0])
def test_mpeg_file_refuses_a_far_plane_rvs_reads_as_infinity(tmp_path, far):
    """An infinite far plane was written as JSON's null, which RVS and TMIV cannot read;
    1000 m or more RVS reads as infinity (its depth maps then decode with 1/far = 0) or
    refuses. Nothing is written."""
    path = tmp_path / "mpeg.json"
    with pytest.raises(ValueError, match="as infinity"):
        mpeg.write_mpeg(path, cameras(), (0.4, far))
    assert not path.exists()
    mpeg.write_mpeg(path, cameras(), (0.4, 999.0))
    assert json.loads(path.read_text())["cameras"][0]["Depth_range"] == [0.4, 999.0]


def test_the_mpeg_views_of_a_failed_export_are_not_left_half_written(tmp_path):
    """A view whose image cannot be read stops the export; the views exported before it
    are not left beside the MPEG file (they were: depth/ and texture/ of the first view,
    an exports review's finding). The same call with every image writes them all."""
    from plenocal.export.mpeg_views import export_views  # noqa: PLC0415

    cams = {k: PinholeCamera(c.K, c.cam_to_world, 300, 224) for k, c in cameras().items()}
    keys = sorted(cams)[:2]
    mpeg.write_mpeg(tmp_path / "cameras.json", cams, (0.4, 0.9))
    depth = {k: np.full((224, 300), 0.6, np.float32) for k in keys}
    images = {keys[0]: np.full((224, 300, 3), 128, np.uint8)}

    def image(key):
        if key not in images:
            raise FileNotFoundError(f"no view image for {key}")
        return images[key]

    with pytest.raises(FileNotFoundError, match=keys[1]):
        export_views(tmp_path, tmp_path / "cameras.json", keys, depth.__getitem__, image, {})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cameras.json"]
    images[keys[1]] = images[keys[0]]
    written = export_views(tmp_path, tmp_path / "cameras.json", keys, depth.__getitem__,
                           image, {"exp1": (keys[:1], keys[1:])})
    assert len(written) == 7 and all((tmp_path / f).is_file() for f in written)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cameras.json", "depth", "rvs",
                                                          "texture"]
