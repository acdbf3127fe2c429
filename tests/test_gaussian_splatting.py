"""The centred dataset for trainers that assume the principal point at the image centre
(plenocal.export.gaussian_splatting): windows and kernels by hand, and views rendered
through off-centre cameras against the same scene rendered through the centred ones."""

import struct

import cv2  # noqa: F401  (before pycolmap)
import numpy as np
import pytest
from synth.scenes import default_scene, render

from plenocal.camera import PinholeCamera, k_from_colmap, pose
from plenocal.export.colmap_model import build_reconstruction
from plenocal.export.gaussian_splatting import (
    centred_window,
    eight_bit,
    export_gaussian_splatting,
    flat_name,
    lanczos_taps,
    shift_crop,
)
from plenocal.io.files import read_image, read_json, write_image

F, W, H = 500.0, 320, 240


@pytest.mark.parametrize("c, size, want", [
    (312.5, 666, (0, 0.5, 624)),  # the default data's hand00/0_0: 20.5 px left of centre
    (333.0, 666, (0, 0.0, 666)),  # centred already: the whole axis
    (330.25, 666, (0, 0.25, 660)),
    (340.0, 666, (14, 0.0, 652)),  # right of centre: the window's left edge moves in
    (1.5, 10, (0, 0.5, 2)),
])
def test_centred_window_by_hand(c, size, want):
    assert centred_window(c, size) == want
    start, frac, n = centred_window(c, size)
    assert start + frac + n / 2 == pytest.approx(c)  # the window's centre is c
    assert start >= 0 and start + n <= size - (frac > 0)


@pytest.mark.parametrize("c", [0.0, -3.0, 10.0, 0.7, 9.6])
def test_no_window_for_a_principal_point_at_or_past_the_border(c):
    with pytest.raises(ValueError, match="principal point"):
        centred_window(c, 10)


def test_lanczos_taps():
    np.testing.assert_array_equal(lanczos_taps(0.0), [0, 0, 1, 0, 0, 0])
    half = lanczos_taps(0.5)
    assert half.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(half, half[::-1])  # half-way: symmetric about the sample
    # a ramp sampled exactly: the weights' first moment is the sample's place (the plain
    # normalised Lanczos kernel's is 0.7698 at 0.75)
    for frac in (0.1, 0.25, 0.5, 0.75, 0.9):
        w = lanczos_taps(frac)
        assert w.sum() == pytest.approx(1.0, abs=1e-14)
        assert w @ (np.arange(6) - 2) == pytest.approx(frac, abs=1e-14)
        assert w[2] > 0.5 if frac < 0.5 else w[3] > 0.5
    with pytest.raises(ValueError):
        lanczos_taps(1.0)


def test_an_integer_window_is_a_plain_crop():
    img = np.random.default_rng(1).integers(0, 65535, (40, 50, 3), dtype=np.uint16)
    out = shift_crop(img, (3, 0.0, 44), (5, 0.0, 30))
    np.testing.assert_array_equal(out, img[5:35, 3:47])


@pytest.mark.parametrize("dtype, tol", [(np.float32, 1e-4), (np.uint8, 0.01)])
def test_a_sub_pixel_dot_moves_with_the_window(dtype, tol):
    """A Gaussian dot at (70.3, 41.8) of the source is at (70.3 - 10.4, 41.8 - 3.75) in a
    window whose first pixel is the source's (10.4, 3.75) (8-bit: to the rounding of the
    source's and the window's pixels)."""
    ys, xs = np.mgrid[0:90, 0:140].astype(np.float64)
    dot = np.exp(-((xs - 70.3) ** 2 + (ys - 41.8) ** 2) / (2 * 2.0 ** 2))
    img = 40 + 200 * dot
    img = np.rint(img).astype(dtype) if dtype == np.uint8 else img.astype(dtype)
    out = shift_crop(img, (10, 0.4, 110), (3, 0.75, 80)).astype(np.float64) - 40
    assert out.shape == (80, 110) and out.dtype == np.float64
    yy, xx = np.mgrid[0:80, 0:110]
    m = out.sum()
    assert (xx * out).sum() / m == pytest.approx(70.3 - 10.4, abs=tol)
    assert (yy * out).sum() / m == pytest.approx(41.8 - 3.75, abs=tol)


def _camera(name: str, dx: float, dy: float, x_m: float) -> PinholeCamera:
    K = np.array([[F, 0, (W - 1) / 2 + dx], [0, F, (H - 1) / 2 + dy], [0, 0, 1]])
    return PinholeCamera(K, pose(np.eye(3), np.array([x_m, 0.0, 0.0])), W, H)


def _legacy_image_names(path) -> list[str]:
    """images.bin read in COLMAP's layout before rigs and frames, as the reference 3D
    Gaussian splatting code reads it (and nothing left over)."""
    data = path.read_bytes()
    (n,), at, names = struct.unpack_from("<Q", data), 8, []
    for _ in range(n):
        at += 4 + 7 * 8 + 4
        end = data.index(b"\0", at)
        names.append(data[at:end].decode())
        (m,) = struct.unpack_from("<Q", data, end + 1)
        at = end + 1 + 8 + 24 * m
    assert at == len(data)
    return names


def _legacy_point_colours(path) -> list[tuple[int, int, int]]:
    """points3D.bin read in COLMAP's layout, as the reference code reads it to start its
    Gaussians (and nothing left over): each point's colour."""
    data = path.read_bytes()
    (n,), at, colours = struct.unpack_from("<Q", data), 8, []
    for _ in range(n):
        colours.append(struct.unpack_from("<QdddBBBd", data, at)[4:7])
        (m,) = struct.unpack_from("<Q", data, at + 43)
        at += 43 + 8 + 8 * m
    assert at == len(data)
    return colours


def test_the_exported_views_are_the_centred_cameras_renders(tmp_path):
    """Views rendered through cameras whose principal points lie off the centre (by whole
    and fractional pixels, either way), exported: each camera is PINHOLE with its principal
    point at its image's centre, each image matches the scene rendered through that
    camera, the points' observations moved with the crops, the names flat, the model
    readable as the reference code reads it, and the same bytes twice."""
    import pycolmap

    cams = {"x00_y00/0_0": _camera("a", 13.3, -7.6, 0.0),
            "x01_y00/0_0": _camera("b", -9.75, 4.2, 0.01),
            "hand00/2_2": _camera("c", 0.0, 0.0, 0.02)}
    scene = default_scene()
    views = {}
    for key, cam in cams.items():
        views[key] = tmp_path / "views" / f"{key}.png"
        views[key].parent.mkdir(parents=True, exist_ok=True)
        write_image(views[key], render(cam, scene))
    rec = build_reconstruction(cams)
    # one 3-D point seen by every view, at its projection there (COLMAP's +0.5)
    X = np.array([0.01, 0.005, 0.6])
    track = pycolmap.Track()
    for image_id, image in rec.images.items():
        uv = cams[image.name[:-4]].project(X[None])[0][0] + 0.5
        image.points2D = pycolmap.Point2DList([pycolmap.Point2D(uv)])
        track.add_element(image_id, 0)
    rec.add_point3D(X, track, np.array([200, 100, 50], np.uint8))
    model = tmp_path / "model"
    model.mkdir()
    rec.write_binary(str(model))

    outs = [tmp_path / f"gs{k}" for k in range(2)]
    for out in outs:
        export_gaussian_splatting(model, out, lambda k: read_image(views[k]), write_image)
    for a, b in zip(sorted(outs[0].rglob("*")), sorted(outs[1].rglob("*")), strict=True):
        assert a.relative_to(outs[0]) == b.relative_to(outs[1])
        if a.is_file():
            assert a.read_bytes() == b.read_bytes(), a
    out = outs[0]
    crops = read_json(out / "crops.json")
    assert crops["format"] == "plenocal.gaussian_splatting" and len(crops["views"]) == 3
    got = pycolmap.Reconstruction(str(out / "sparse" / "0"))
    assert got.num_points3D() == 1
    names = _legacy_image_names(out / "sparse" / "0" / "images.bin")
    assert sorted(names) == sorted(flat_name(f"{k}.png") for k in cams)
    assert len({n.split(".")[0] for n in names}) == 3  # the reference code's image names
    assert _legacy_point_colours(out / "sparse" / "0" / "points3D.bin") == [(200, 100, 50)]
    key_of = {v["image"]: k for k, v in crops["views"].items()}
    for image in got.images.values():
        key = key_of[image.name]
        cam = got.camera(image.camera_id)
        fx, fy, cx, cy = cam.params
        assert (cam.model.name, fx, fy) == ("PINHOLE", F, F)
        assert (cx, cy) == (cam.width / 2, cam.height / 2)
        assert cam.width % 2 == 0 and cam.width <= W and cam.height <= H
        centred = PinholeCamera(k_from_colmap(cam.calibration_matrix()),
                                cams[key].cam_to_world, cam.width, cam.height)
        # the observation moved with the crop: where the centred camera projects the point
        uv = centred.project(X[None])[0][0] + 0.5
        np.testing.assert_allclose(image.points2D[0].xy, uv, atol=1e-9)
        # the image: the scene through the centred camera, to the resampling's error
        img = read_image(out / "images" / image.name).astype(np.float64)
        want = render(centred, scene).astype(np.float64)
        assert img.shape == want.shape
        err = np.abs(img - want)[8:-8, 8:-8].mean()
        start = crops["views"][key]["origin_px"]
        unshifted = read_image(views[key])[int(start[1]):int(start[1]) + cam.height,
                                           int(start[0]):int(start[0]) + cam.width]
        err_unshifted = np.abs(unshifted - want)[8:-8, 8:-8].mean()
        assert err < 2.0, (key, err)
        if (start[0] % 1, start[1] % 1) != (0, 0):  # the fraction matters
            assert err < 0.7 * err_unshifted, (key, err, err_unshifted)


def test_a_camera_with_distortion_is_refused(tmp_path):
    import pycolmap

    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(
        camera_id=1, model="SIMPLE_RADIAL", width=W, height=H, params=[F, W / 2, H / 2, 0.01]))
    rec.write_binary(str(tmp_path))
    with pytest.raises(ValueError, match="SIMPLE_RADIAL.*PINHOLE"):
        export_gaussian_splatting(tmp_path, tmp_path / "gs", lambda k: None, write_image)
    assert not (tmp_path / "gs").exists()


def test_a_view_of_another_size_than_its_camera_is_refused(tmp_path):
    cams = {"x00_y00/0_0": _camera("a", 3.0, 0.0, 0.0)}
    model = tmp_path / "model"
    model.mkdir()
    build_reconstruction(cams).write_binary(str(model))
    small = np.zeros((H // 2, W // 2, 3), np.uint8)
    with pytest.raises(ValueError, match=r"x00_y00/0_0 is 160x120 px, its camera 320x240"):
        export_gaussian_splatting(model, tmp_path / "gs", lambda k: small, write_image)
    assert not (tmp_path / "gs").exists()


def test_sixteen_bit_views_are_written_in_eight_bits():
    v = np.array([[0, 128, 129, 257, 32896, 65535]], np.uint16)
    np.testing.assert_array_equal(eight_bit(v), [[0, 0, 1, 1, 128, 255]])
    same = np.arange(256, dtype=np.uint8)
    assert eight_bit(same) is same
    with pytest.raises(TypeError):
        eight_bit(v.astype(np.float32))
