"""The COLMAP boundary: image staging, SIFT extraction, matching, the conversions
between COLMAP's reconstruction and the internal convention, and the sparse points an
image of registration A's model sees (:func:`model_points`, for the depth bounds).

COLMAP stores cam_from_world and puts the centre of pixel (0, 0) at (0.5, 0.5); the
project uses camera-to-world poses and pixel centres at integers (DESIGN.md). Every
crossing goes through :func:`pinhole_from_colmap` or :func:`known_pose_reconstruction`
(``plenocal.camera.k_to_colmap``/``k_from_colmap``), nowhere else.

Determinism: pycolmap's PRNG is seeded (``pycolmap.set_random_seed``) and RANSAC gets
an explicit seed; images are imported in sorted name order, so image ids, and
everything downstream, do not depend on the file system.

``pycolmap`` is imported inside the functions: a process must import cv2 first
(DESIGN.md, Known traps).
"""

from __future__ import annotations

import logging
import shutil
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from plenocal.camera import PinholeCamera, invert_pose, k_from_colmap, k_to_colmap
from plenocal.config import stage_defaults
from plenocal.gpu import resolve_device
from plenocal.io.png import damage

log = logging.getLogger(__name__)


def stage_images(images: Mapping[str, str | Path], folder: str | Path,
                 ext: str = ".png") -> list[str]:
    """Copy ``images`` (name -> source file) to ``folder/<name><ext>``; names may hold
    '/' (sub-folders, e.g. ``<cam>/<view>``). Returns the COLMAP image names, sorted."""
    folder = Path(folder)
    names = []
    for name in sorted(images):
        src = Path(images[name])
        if not src.is_file():
            raise FileNotFoundError(f"{src}: image of view {name!r} not found; run the "
                                    "convert stage first (or check the dataset folder)")
        cut = damage(src)
        if cut is not None:  # named here: the copy that fails to decode is a temporary one
            raise OSError(f"{src}: the image of view {name!r} is {cut}; delete it and run "
                          "again to make it anew (a view changed by hand is not noticed)")
        dst = folder / f"{name}{ext}"
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst)
        names.append(f"{name}{ext}")
    return names


def image_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of an image file."""
    from plenocal.io.files import read_image  # noqa: PLC0415

    img = read_image(path)
    return int(img.shape[1]), int(img.shape[0])


#: COLMAP's SIFT default: the scale space starts on the image upsampled 2x
DEFAULT_FIRST_OCTAVE = -1
#: SIFT's DoG peak threshold as OpenCV's ``contrastThreshold`` (COLMAP's default
#: ``peak_threshold`` 0.02 / 3 with 3 scales per octave: OpenCV divides by them itself)
DEFAULT_CONTRAST = 0.02

#: SIFT implementations (config ``sfm.sift``): OpenCV's, set up as COLMAP's (about 6x
#: faster than COLMAP's on one core), or COLMAP's own (SiftGPU on a GPU); the config's
#: ``auto`` is one of them (:func:`resolve_extractor`)
EXTRACTORS = ("opencv", "colmap")
#: the keyword defaults of the COLMAP steps: config.schema.yaml's sfm block
SFM_DEFAULTS = stage_defaults("sfm")
DEFAULT_EXTRACTOR = "opencv"  # sfm.sift auto on the CPU
DEFAULT_MAX_FEATURES = SFM_DEFAULTS["max_num_features"]
DEFAULT_SEED, DEFAULT_THREADS = SFM_DEFAULTS["seed"], SFM_DEFAULTS["num_threads"]


def resolve_extractor(sift: str, use_gpu: bool) -> str:
    """The SIFT implementation of config ``sfm.sift``: ``auto`` -> ``colmap`` (SiftGPU)
    where the SfM steps use the GPU (``use_gpu``, :func:`resolve_sfm_device`), else
    ``opencv``; ``opencv`` or ``colmap`` as they are (OpenCV's SIFT runs on the CPU
    either way)."""
    if sift == "auto":
        return "colmap" if use_gpu else "opencv"
    if sift not in EXTRACTORS:
        raise ValueError(f"SIFT extractor {sift!r}: use auto or one of {', '.join(EXTRACTORS)} "
                         "(config key sfm.sift)")
    return sift


def resolve_sfm_device(sfm: Mapping) -> tuple[bool, str]:
    """(use the GPU, SIFT extractor) of the config's ``sfm`` block: ``sfm.device``
    resolved by :func:`plenocal.gpu.resolve_device` (``auto``: the GPU where COLMAP's
    CUDA code can run), then ``sfm.sift`` (:func:`resolve_extractor`)."""
    use_gpu = resolve_device(sfm["device"], "sfm.device") == "cuda"
    return use_gpu, resolve_extractor(sfm["sift"], use_gpu)


def sift_device(extractor: str, use_gpu: bool) -> str:
    """Where ``extractor``'s SIFT runs: ``cuda`` for COLMAP's with ``use_gpu`` (SiftGPU),
    else ``cpu`` (OpenCV's always)."""
    return "cuda" if use_gpu and extractor == "colmap" else "cpu"


def _device(use_gpu: bool):
    """pycolmap's Device: ``cuda`` with ``use_gpu``, else ``cpu``."""
    import pycolmap  # noqa: PLC0415

    return pycolmap.Device.cuda if use_gpu else pycolmap.Device.cpu


def _extraction_options(max_num_features: int, num_threads: int,
                        first_octave: int = DEFAULT_FIRST_OCTAVE, use_gpu: bool = False,
                        contrast: float = DEFAULT_CONTRAST):
    """SIFT settings: COLMAP's defaults but the feature cap and the first octave
    (``first_octave`` 0: the scale space starts at the image's own resolution, about a
    third of the time of COLMAP's -1 and half the keypoints; see README, SIFT);
    ``use_gpu``: SiftGPU on the first GPU; ``contrast``: the DoG peak threshold as OpenCV
    gives it (:data:`DEFAULT_CONTRAST`), COLMAP's a third of it."""
    import pycolmap  # noqa: PLC0415

    opts = pycolmap.FeatureExtractionOptions()
    opts.num_threads = num_threads
    opts.use_gpu = use_gpu
    opts.sift.max_num_features = max_num_features
    opts.sift.first_octave = first_octave
    opts.sift.peak_threshold = contrast / 3.0
    return opts


def extract_features(database: str | Path, image_dir: str | Path,
                     groups: list[tuple[list[str], PinholeCamera | None]], *,
                     model: str = "PINHOLE",
                     max_num_features: int = DEFAULT_MAX_FEATURES,
                     num_threads: int = DEFAULT_THREADS, seed: int = DEFAULT_SEED,
                     first_octave: int = DEFAULT_FIRST_OCTAVE,
                     extractor: str = DEFAULT_EXTRACTOR, use_gpu: bool = False,
                     contrast: float = DEFAULT_CONTRAST) -> None:
    """SIFT into a new database. ``groups``: (image names, camera) pairs; all images of
    a group share one COLMAP camera. A group's camera, where given, is written with its
    intrinsics (``model`` PINHOLE or SIMPLE_PINHOLE, marked as a known focal length);
    where None, the camera gets COLMAP's default focal (1.2 max(W, H)) and the principal
    point at the image centre. ``first_octave``: SIFT's first octave
    (:func:`_extraction_options`). ``extractor``: ``"opencv"`` (:func:`opencv_sift`,
    COLMAP's settings, first octave -1 only, on the CPU) or ``"colmap"`` (COLMAP's own
    SIFT: SiftGPU with ``use_gpu``, else its CPU SIFT); the images, cameras and frames
    are COLMAP's import either way. ``contrast``: SIFT's DoG peak threshold
    (:data:`DEFAULT_CONTRAST`)."""
    if extractor not in EXTRACTORS:
        raise ValueError(f"SIFT extractor {extractor!r}: use one of {', '.join(EXTRACTORS)} "
                         "(config key sfm.sift)")
    device = _device(sift_device(extractor, use_gpu) == "cuda")
    if extractor == "opencv" and first_octave != -1:
        raise ValueError(f"OpenCV's SIFT starts on the image upsampled 2x (first octave -1),"
                         f" not {first_octave}: use sfm.sift colmap for another first octave")
    import pycolmap  # noqa: PLC0415

    pycolmap.set_random_seed(seed)
    database = Path(database)
    if database.exists():
        database.unlink()
    database.parent.mkdir(parents=True, exist_ok=True)
    for names, cam in groups:
        if not names:
            continue
        names = sorted(names)
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = model
        if cam is not None:
            K = k_to_colmap(cam.K)
            if model == "SIMPLE_PINHOLE":
                params = [0.5 * (K[0, 0] + K[1, 1]), K[0, 2], K[1, 2]]
            else:
                params = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
            camera = pycolmap.Camera.create_from_model_name(0, model, 1.0, int(cam.width),
                                                            int(cam.height))
            camera.params = params
            camera.has_prior_focal_length = True
            with pycolmap.Database.open(str(database)) as db:
                cam_id = db.write_camera(camera)
            reader.existing_camera_id = cam_id
        if extractor == "colmap":
            pycolmap.extract_features(str(database), str(image_dir), image_names=names,
                                      camera_mode=pycolmap.CameraMode.SINGLE,
                                      reader_options=reader,
                                      extraction_options=_extraction_options(
                                          max_num_features, num_threads, first_octave,
                                          use_gpu, contrast),
                                      device=device)
        else:
            with pycolmap.Database.open(str(database)):
                pass  # created with COLMAP's schema: import_images needs the file
            pycolmap.import_images(str(database), str(image_dir),
                                   camera_mode=pycolmap.CameraMode.SINGLE, image_names=names,
                                   options=reader)
            _write_opencv_sift(database, Path(image_dir), set(names), max_num_features,
                               contrast)
        log.info("features (%s SIFT, %s): %d images of group %s", extractor,
                 sift_device(extractor, use_gpu), len(names), names[0])


def _write_opencv_sift(database: Path, image_dir: Path, names: set[str],
                       max_num_features: int, contrast: float = DEFAULT_CONTRAST) -> None:
    """:func:`opencv_sift` of the imported images ``names`` into ``database``."""
    import cv2  # noqa: PLC0415
    import pycolmap  # noqa: PLC0415

    with pycolmap.Database.open(str(database)) as db:
        for im in sorted(db.read_all_images(), key=lambda i: i.image_id):
            if im.name not in names:
                continue
            gray = cv2.imread(str(image_dir / im.name), cv2.IMREAD_GRAYSCALE)
            if gray is None:
                raise OSError(f"{image_dir / im.name}: not a readable image")
            kp, desc = opencv_sift(gray, max_num_features, contrast)
            db.write_keypoints(im.image_id, kp)
            db.write_descriptors(im.image_id, pycolmap.FeatureDescriptors(
                pycolmap.FeatureExtractorType.SIFT, desc))


def opencv_sift(gray: np.ndarray, max_num_features: int = DEFAULT_MAX_FEATURES,
                contrast: float = DEFAULT_CONTRAST) -> tuple[np.ndarray, np.ndarray]:
    """SIFT (Lowe 2004) of an 8-bit grey image by OpenCV, set up as COLMAP's CPU SIFT:
    3 scales per octave, first octave -1 (the image upsampled 2x, pixel-aligned as
    VLFeat's: OpenCV's plain upscale would shift every keypoint by +0.25 px), sigma 1.6, DoG peak
    threshold 0.02 / 3 (OpenCV's ``contrastThreshold`` 0.02 is that threshold), edge
    threshold 10, RootSIFT descriptors (L1-normalised, square-rooted) stored as
    ``round(512 d)`` in uint8 as COLMAP stores them, keypoints in COLMAP's pixel
    convention (centre of pixel (0, 0) at (0.5, 0.5)). At most ``max_num_features``,
    the strongest. ``contrast``: the DoG peak threshold (OpenCV's ``contrastThreshold``;
    lower keeps weaker extrema). Single-threaded and deterministic.

    Returns (N, 4) float32 keypoints (x, y, scale, orientation in radians) and (N, 128)
    uint8 descriptors, in OpenCV's order. On the default data's 500 x 376 views: about
    6x faster than COLMAP's extractor (0.04 against 0.28 CPU s per view, issue 15)."""
    import cv2  # noqa: PLC0415

    if gray.dtype != np.uint8 or gray.ndim != 2:
        raise TypeError(f"opencv_sift needs an 8-bit grey image, got {gray.dtype} "
                        f"{gray.shape}")
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # OpenCV's parallel loops could reorder the keypoints
    try:
        sift = cv2.SIFT_create(nfeatures=int(max_num_features), nOctaveLayers=3,
                               contrastThreshold=float(contrast), edgeThreshold=10.0,
                               sigma=1.6,
                               enable_precise_upscale=True)
        keypoints, desc = sift.detectAndCompute(gray, None)
    finally:
        cv2.setNumThreads(threads)
    kp = np.zeros((len(keypoints), 4), dtype=np.float32)
    if not keypoints:
        return kp, np.zeros((0, 128), dtype=np.uint8)
    kp[:, 0] = [k.pt[0] + 0.5 for k in keypoints]
    kp[:, 1] = [k.pt[1] + 0.5 for k in keypoints]
    kp[:, 2] = [k.size / 2 for k in keypoints]
    kp[:, 3] = [np.deg2rad(k.angle) for k in keypoints]
    return kp, root_sift_uint8(desc)


def root_sift_uint8(desc: np.ndarray) -> np.ndarray:
    """COLMAP's L1_ROOT normalisation and uint8 storage of SIFT descriptors (N, 128):
    ``d / |d|_1``, element-wise square root (unit L2 norm), then ``min(round(512 d),
    255)``."""
    d = np.asarray(desc, dtype=np.float64)
    total = d.sum(axis=1, keepdims=True)
    d = np.sqrt(d / np.where(total > 0, total, 1.0))
    return np.minimum(np.rint(512.0 * d), 255).astype(np.uint8)


def _verification_options(seed: int, max_error_px: float = 4.0):
    import pycolmap  # noqa: PLC0415

    opts = pycolmap.TwoViewGeometryOptions()
    opts.ransac.random_seed = seed
    opts.ransac.max_error = max_error_px
    return opts


def _matching_options(num_threads: int, use_gpu: bool = False):
    import pycolmap  # noqa: PLC0415

    opts = pycolmap.FeatureMatchingOptions()
    opts.num_threads = num_threads
    opts.use_gpu = use_gpu
    return opts


def match(database: str | Path, pairs: Iterable[tuple[str, str]] | None = None, *,
          seed: int = DEFAULT_SEED, num_threads: int = DEFAULT_THREADS,
          work_dir: str | Path | None = None, use_gpu: bool = False,
          per_image_verification: bool = False) -> int:
    """Match and geometrically verify: every pair (``pairs`` None: exhaustive) or the
    given image-name pairs; ``use_gpu``: the descriptors are matched by COLMAP's GPU
    matcher (the verification runs on the CPU either way). ``per_image_verification``
    (given pairs only): matched and verified as pairs of two cameras
    (:func:`_match_per_image`), the database's own cameras untouched.
    Returns the number of verified pairs."""
    import pycolmap  # noqa: PLC0415

    device = _device(use_gpu)
    pycolmap.set_random_seed(seed)
    database = Path(database)
    if per_image_verification:
        if pairs is None:
            raise ValueError("per-image verification needs the pairs to match")
        _match_per_image(database, pairs, seed=seed, num_threads=num_threads,
                         work_dir=work_dir, use_gpu=use_gpu)
    elif pairs is None:
        pycolmap.match_exhaustive(str(database),
                                  matching_options=_matching_options(num_threads, use_gpu),
                                  verification_options=_verification_options(seed),
                                  device=device)
    else:
        _match_pair_list(database, pairs, seed=seed, num_threads=num_threads,
                         work_dir=work_dir, use_gpu=use_gpu)
    with pycolmap.Database.open(str(database)) as db:
        n = db.num_verified_image_pairs()
    log.info("matching: %d verified image pairs", n)
    return n


def _match_pair_list(database: Path, pairs: Iterable[tuple[str, str]], *, seed: int,
                     num_threads: int, work_dir: str | Path | None, use_gpu: bool) -> None:
    """COLMAP's matching and verification of the image-name ``pairs`` in ``database``,
    through a pair list written beside it (under ``work_dir``) and removed after."""
    import pycolmap  # noqa: PLC0415

    pair_file = Path(work_dir or database.parent) / f".{database.stem}.pairs.txt"
    try:
        pair_file.write_text("".join(f"{a} {b}\n" for a, b in pairs))
        popts = pycolmap.ImportedPairingOptions()
        popts.match_list_path = str(pair_file)
        pycolmap.match_image_pairs(str(database),
                                   matching_options=_matching_options(num_threads, use_gpu),
                                   pairing_options=popts,
                                   verification_options=_verification_options(seed),
                                   device=_device(use_gpu))
    finally:
        pair_file.unlink(missing_ok=True)


def _match_per_image(database: Path, pairs: Iterable[tuple[str, str]], *, seed: int,
                     num_threads: int, work_dir: str | Path | None, use_gpu: bool) -> None:
    """Match ``pairs`` and verify them with every image its own camera (copies of the
    database's), in a scratch copy of ``database``; then its ``matches`` and
    ``two_view_geometries`` rows are written into ``database``, whose cameras, rigs and
    frames stay as they were.

    Why: pycolmap 4.2 verifies a pair of images that share one camera without a focal
    prior (the view database's layout) with COLMAP's shared-focal estimator (PoseLib's
    6-point solver and a Sampson refinement of pose and focal length), about 3.5x the
    time of the fundamental-matrix path that a pair of two cameras takes (29.8 s against
    8.5 s for the default data's 2991 pairs, the same configurations and inlier counts
    within 0.7 %; BENCHMARKS.md, "The view matches verified per image"). The matching
    itself reads descriptors only; the image ids, and so the pair ids, are the
    database's."""
    import contextlib  # noqa: PLC0415
    import sqlite3  # noqa: PLC0415

    scratch = Path(work_dir or database.parent) / f".{database.stem}.per_image.db"
    scratch.unlink(missing_ok=True)
    try:
        with contextlib.closing(sqlite3.connect(database)) as con:
            con.execute("VACUUM INTO ?", (str(scratch),))
        with contextlib.closing(sqlite3.connect(scratch)) as con:
            _one_camera_per_image(con)
            con.commit()
        _match_pair_list(scratch, pairs, seed=seed, num_threads=num_threads,
                         work_dir=work_dir, use_gpu=use_gpu)
        with contextlib.closing(sqlite3.connect(database)) as con:
            con.execute("ATTACH DATABASE ? AS scratch", (str(scratch),))
            for table in ("matches", "two_view_geometries"):
                con.execute(f"DELETE FROM main.{table}")
                con.execute(f"INSERT INTO main.{table} SELECT * FROM scratch.{table} "
                            "ORDER BY pair_id")
            con.commit()
            con.execute("DETACH DATABASE scratch")
    finally:
        for path in (scratch, Path(f"{scratch}-wal"), Path(f"{scratch}-shm")):
            path.unlink(missing_ok=True)


def check_database(database: str | Path, remedy: str) -> int:
    """The number of images in the COLMAP database ``database``, opened as immutable (a
    read-only connection to COLMAP's WAL-mode file leaves ``-wal`` and ``-shm`` files
    beside a rule's input; immutable reads the main file alone, so one with a ``-wal``
    file of its own is refused); an error naming the file and ``remedy`` where it is missing,
    cut short or not a COLMAP database (pycolmap's own answer, "No registered database
    factory succeeded", names neither)."""
    import contextlib  # noqa: PLC0415
    import sqlite3  # noqa: PLC0415

    path = Path(database)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: COLMAP database not found; {remedy}")
    wal = Path(f"{path}-wal")
    if wal.is_file() and wal.stat().st_size > 0:
        # writes not folded into the file yet: a COLMAP still writing it, or one killed
        raise ValueError(f"{path}: holds writes not yet folded in ({wal.name} beside it: "
                         f"a COLMAP still writing it, or one stopped); {remedy}")
    try:
        uri = path.resolve().as_uri() + "?immutable=1"
        with contextlib.closing(sqlite3.connect(uri, uri=True)) as con:
            state = con.execute("PRAGMA quick_check").fetchone()[0]
            images = int(con.execute("SELECT count(*) FROM images").fetchone()[0])
    except sqlite3.DatabaseError as exc:
        raise ValueError(f"{path}: not a readable COLMAP database ({exc}); {remedy}") \
            from None
    if state != "ok":
        raise ValueError(f"{path}: a damaged COLMAP database ({state}); {remedy}")
    return images


def _one_camera_per_image(con) -> None:
    """Rewrite an open COLMAP database (sqlite3 connection) so that every image has a
    camera of its own, a copy of its camera (camera id = image id), in a rig and a frame
    of its own, as COLMAP's per-image import lays them out."""
    rows = con.execute("SELECT image_id, camera_id FROM images ORDER BY image_id").fetchall()
    cams = {r[0]: r[1:] for r in con.execute(
        "SELECT camera_id, model, width, height, params, prior_focal_length FROM cameras")}
    con.execute("DELETE FROM frame_data")
    con.execute("DELETE FROM frames")
    con.execute("DELETE FROM rig_sensors")
    con.execute("DELETE FROM rigs")
    con.execute("DELETE FROM cameras")
    con.executemany("INSERT INTO cameras (camera_id, model, width, height, params, "
                    "prior_focal_length) VALUES (?, ?, ?, ?, ?, ?)",
                    [(image_id, *cams[camera_id]) for image_id, camera_id in rows])
    ids = [(image_id,) * 2 for image_id, _ in rows]
    con.executemany("UPDATE images SET camera_id = ? WHERE image_id = ?", ids)
    con.executemany("INSERT INTO rigs (rig_id, ref_sensor_id, ref_sensor_type) "
                    "VALUES (?, ?, 0)", ids)
    con.executemany("INSERT INTO frames (frame_id, rig_id) VALUES (?, ?)", ids)
    con.executemany("INSERT INTO frame_data (frame_id, data_id, sensor_id, sensor_type) "
                    "VALUES (?, ?, ?, 0)", [(i, i, i) for i, _ in ids])


def pinhole_from_colmap(image, camera) -> PinholeCamera:
    """A registered ``pycolmap.Image`` and its ``pycolmap.Camera`` in the internal
    convention (camera-to-world, pixel centres at integers)."""
    K = k_from_colmap(np.asarray(camera.calibration_matrix(), dtype=float))
    M = np.eye(4)
    M[:3, :] = np.asarray(image.cam_from_world().matrix(), dtype=float)
    return PinholeCamera(K, invert_pose(M), int(camera.width), int(camera.height))


def _rigid(cam_to_world: np.ndarray):
    import pycolmap  # noqa: PLC0415

    M = invert_pose(np.asarray(cam_to_world, dtype=float))
    U, _, Vt = np.linalg.svd(M[:3, :3])
    return pycolmap.Rigid3d(pycolmap.Rotation3d(U @ Vt), M[:3, 3].copy())


def known_pose_reconstruction(database: str | Path, cameras: Mapping[str, PinholeCamera],
                              update_intrinsics: bool = True):
    """A ``pycolmap.Reconstruction`` with the database's cameras, rigs, frames and
    images (their ids: ``triangulate_points`` needs them, DESIGN.md Known traps), every
    image of ``cameras`` (keyed by COLMAP image name) registered at its known pose and,
    with ``update_intrinsics``, its camera set to the known K. Images of the database
    absent from ``cameras`` stay unregistered."""
    import pycolmap  # noqa: PLC0415

    rec = pycolmap.Reconstruction()
    with pycolmap.Database.open(str(database)) as db:
        db_cams = {c.camera_id: c for c in db.read_all_cameras()}
        rigs = db.read_all_rigs()
        frames = db.read_all_frames()
        images = db.read_all_images()
    by_name = {im.name: im for im in images}
    missing = sorted(set(cameras) - set(by_name))
    if missing:
        raise ValueError(f"views not in the database {database}: {', '.join(missing[:10])}")
    for name, cam in cameras.items():
        c = db_cams[by_name[name].camera_id]
        if (int(c.width), int(c.height)) != (int(cam.width), int(cam.height)):
            raise ValueError(f"{name}: image is {c.width}x{c.height}, the calibration says "
                             f"{cam.width}x{cam.height}")
        if update_intrinsics:
            K = k_to_colmap(cam.K)
            if c.model_name == "SIMPLE_PINHOLE":
                c.params = [0.5 * (K[0, 0] + K[1, 1]), K[0, 2], K[1, 2]]
            else:
                c.params = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
    for cid in sorted(db_cams):
        rec.add_camera(db_cams[cid])
    for rig in rigs:
        rec.add_rig(rig)
    image_of_frame = {im.frame_id: im for im in images}
    for frame in frames:
        im = image_of_frame.get(frame.frame_id)
        if im is not None and im.name in cameras:
            frame.rig_from_world = _rigid(cameras[im.name].cam_to_world)
        rec.add_frame(frame)
    for im in sorted(images, key=lambda i: i.image_id):
        rec.add_image(pycolmap.Image(name=im.name, camera_id=im.camera_id,
                                     image_id=im.image_id, frame_id=im.frame_id))
    for frame in frames:
        im = image_of_frame.get(frame.frame_id)
        if im is not None and im.name in cameras:
            rec.register_frame(frame.frame_id)
    return rec


def model_points(model_dir: str | Path, image_name: str) -> np.ndarray:
    """(n, 3) world coordinates of the sparse points that image ``image_name`` of the
    COLMAP model in ``model_dir`` observes; of every point of the model where no image has
    that name."""
    import pycolmap  # noqa: PLC0415

    rec = pycolmap.Reconstruction(str(model_dir))
    image = next((im for im in rec.images.values() if im.name == image_name), None)
    if image is None:
        pts = [p.xyz for p in rec.points3D.values()]
    else:
        pts = [rec.points3D[p.point3D_id].xyz for p in image.points2D if p.has_point3D()]
    return np.array(pts, dtype=float).reshape(-1, 3)
