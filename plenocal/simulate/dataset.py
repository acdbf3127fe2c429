"""Write a synthetic dataset: shots, scene, optics, ``calib.xml``, ``camera.yaml``
and the lenslet images (DESIGN.md "The simulator, and ground truth")."""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import fields
from pathlib import Path

import numpy as np
import yaml

from plenocal.camera import pose
from plenocal.config import with_defaults
from plenocal.grid import MicrolensGrid
from plenocal.io.files import (
    LENSLET_PNG_LEVEL,
    atomic_write_text,
    read_json,
    write_image,
    write_json,
)
from plenocal.io.raytrix import read_calib, write_calib
from plenocal.names import array_shot, array_shots, handheld_shot, handheld_shots
from plenocal.optics import PlenopticOptics
from plenocal.simulate.mla import lens_type_map, make_calib
from plenocal.simulate.optics_setup import optics_from_config
from plenocal.simulate.raytrace import (
    LensletSetup,
    nearest_lens_centres,
    prepare_lenslet,
    trace_lenslet,
)
from plenocal.simulate.scene import SceneArrays, make_scene, pack_textures, scene_arrays
from plenocal.simulate.sensor import natural_vignetting, read_out


def shot_names(sim: dict) -> list[str]:
    a = sim["array"]
    return array_shots(a["cols"], a["rows"]) + handheld_shots(sim["handheld"]["count"])


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def make_shots(sim: dict, scene_centre: np.ndarray) -> dict[str, np.ndarray]:
    """Camera-to-world poses (main-lens centre frame) of every shot.

    Array shots sit on a stage at (col step, row step, 0) looking along +z. Hand-held
    shots orbit the scene centre: a random rotation (up to ``max_rotation_deg`` about
    a random axis) turns the camera about the scene centre, then a random offset (up
    to ``max_offset_m`` per axis) moves it, so that every shot sees the scene. The turns
    and offsets are drawn from ``handheld.seed`` where it is given, else from ``seed``.
    """
    a = sim["array"]
    step = a["step_m"]
    shots = {}
    for r in range(a["rows"]):
        for c in range(a["cols"]):
            shots[array_shot(c, r)] = pose(np.eye(3), np.array([c * step, r * step, 0.0]))
    hh = sim["handheld"]
    # the poses' own seed where given (it has no schema default: absent, the scene's)
    rng = np.random.default_rng([hh["seed"] if "seed" in hh else sim["seed"], 3])
    centre_array = np.array([(a["cols"] - 1) * step / 2, (a["rows"] - 1) * step / 2, 0.0])
    dist = float(np.linalg.norm(scene_centre - centre_array))
    for k in range(hh["count"]):
        axis = rng.normal(size=3)
        angle = math.radians(hh["max_rotation_deg"]) * math.sqrt(rng.uniform(0.25, 1.0))
        R = _axis_angle(axis, angle)
        offset = rng.uniform(-1, 1, size=3) * hh["max_offset_m"]
        C = scene_centre - R @ np.array([0.0, 0.0, dist]) + offset
        shots[handheld_shot(k)] = pose(R, C)
    return shots


def datasheet(sim: dict, optics: PlenopticOptics) -> dict:
    """What a datasheet (and a tape measure) gives: the values registration B needs."""
    def mm(metres: float) -> float:
        return round(metres * 1e3, 9)  # no binary round-off (0.12999999999999998) in the file

    return {
        "pixel_size_mm": mm(optics.pixel_size),
        "sensor_width_px": optics.width,
        "sensor_height_px": optics.height,
        "main_lens": {"focal_length_mm": mm(optics.focal_length),
                      "focus_distance_mm": mm(optics.focus_distance)},
        "mla": {"pitch_mm": mm(optics.mla_pitch),
                "f_numbers": [round(optics.mla_f_number * r, 9) for r in optics.type_focal_ratios],
                "k": optics.k, "sensor_distance_mm": mm(optics.s)},
        "array": {"step_mm": mm(sim["array"]["step_m"])},
        "scene": {"near_mm": mm(sim["scene"]["near_m"]), "far_mm": mm(sim["scene"]["far_m"])},
    }


CAMERA_YAML_HEADER = """\
# Datasheet values of the (simulated) plenoptic camera, as registration B reads them.
# pixel_size_mm: sensor pixel pitch p; sensor_*_px: lenslet image size.
# main_lens.focus_distance_mm: X_o, from the main lens; focal_length_mm: nominal only
#   (registration B derives F from registration A's focal length, as the paper does).
# mla.pitch_mm: physical microlens pitch D; f_numbers: microlens F-number(s) (the paper
#   uses the middle one); k: the paper's k (s = k f / (k - 1) behind a Keplerian MLA,
#   k f / (k + 1) behind a Galilean one); sensor_distance_mm: s.
# array.step_mm: stage step between array shots.
# scene.near_mm / far_mm: measured nearest / farthest object distances (Eqs. 2-3 check).
"""


def setup_dataset(sim: dict, out_dir: str | Path) -> None:
    """Write truth/{scene,shots,optics}.json, calib.xml and camera.yaml (``sim``: a
    dataset's ``simulate`` block, partial or whole)."""
    sim = with_defaults("simulate", sim)
    out = Path(out_dir)
    optics = optics_from_config(sim)
    a = sim["array"]
    centre_xy = ((a["cols"] - 1) * a["step_m"] / 2, (a["rows"] - 1) * a["step_m"] / 2)
    scene = make_scene(centre_xy, sim["scene"]["near_m"], sim["scene"]["far_m"], sim["seed"])
    shots = make_shots(sim, np.array(scene["centre"]))
    calib = make_calib(sim, optics)
    write_json(out / "truth" / "scene.json", scene)
    write_json(out / "truth" / "shots.json",
               {k: {"cam_to_world": v} for k, v in sorted(shots.items())})
    grid = MicrolensGrid(calib, optics.width, optics.height)
    write_json(out / "truth" / "optics.json",
               {**optics.to_dict(), "mla_rotation_rad": calib.rotation,
                "mla_offset_px": list(calib.offset), "seed": sim["seed"],
                "grid": {"micro_image_pitch_px": calib.diameter,
                         "origin_px": [float(x) for x in grid.origin],
                         "lens_border_px": calib.lens_border, "lenses": len(grid),
                         "lenses_whole": int(grid.inside().sum()),
                         "virtual_depth_near": float(optics.virtual_depth(sim["scene"]["near_m"])),
                         "virtual_depth_far": float(optics.virtual_depth(sim["scene"]["far_m"])),
                         "virtual_depth_focus": calib.tcp,
                         "lens_types": [{"id": t.id, "focal_length": optics.type_f(t.id),
                                         "sharp_virtual_depth": 1.0 / optics.type_kappa(t.id),
                                         "depth_range": [t.depth_min, t.depth_max]}
                                        for t in calib.lens_types]},
                "sensor": sensor_truth(sim)})
    write_calib(calib, out / "calib.xml")
    atomic_write_text(out / "camera.yaml",
                      CAMERA_YAML_HEADER + yaml.safe_dump(datasheet(sim, optics),
                                                          sort_keys=True))


def optics_from_truth(path: str | Path) -> PlenopticOptics:
    """The simulated camera's optics from ``truth/optics.json``: the fields of
    :class:`PlenopticOptics` (its ``to_dict`` wrote them there, beside derived values)."""
    d = read_json(path)
    names = [f.name for f in fields(PlenopticOptics)]
    missing = [k for k in names if k not in d]
    if missing:
        raise ValueError(f"{path}: no {', '.join(missing)} (written by an older simulator); "
                         "rerun rule simulate_setup")
    return PlenopticOptics(**{**{k: d[k] for k in names}, "width": int(d["width"]),
                              "height": int(d["height"]),
                              "type_focal_ratios": tuple(d["type_focal_ratios"])})


def sensor_truth(sim: dict) -> dict:
    """The readout and vignetting settings a shot is rendered with (truth/optics.json),
    from a validated ``simulate`` block."""
    sensor, vig = sim["sensor"], sim["main_lens"]["vignetting"]
    return {"bit_depth": int(sensor["bit_depth"]),
            "noise_std": float(sensor["noise_std"]),
            "full_well_e": sensor["full_well_e"],
            "vignetting_cos4": bool(vig["cos4"]),
            "front_stop_distance_m": float(vig["stop_distance_mm"]) / 1000.0,
            "front_stop_diameter_scale": float(vig["stop_diameter_scale"])}


def nearest_lens_map(grid: MicrolensGrid) -> np.ndarray:
    """(H, W, 2) micro-image centre of the nearest lens for every sensor pixel."""
    return nearest_lens_centres(grid.origin, grid.A, grid.width, grid.height)


def white_scene() -> SceneArrays:
    """A white plane far away, filling every ray's view (Raytrix's white image)."""
    w, z = 200.0, 50.0
    return SceneArrays(p0=np.array([[-w / 2, -w / 2, z]]), u=np.array([[w, 0.0, 0.0]]),
                       v=np.array([[0.0, w, 0.0]]), normal=np.array([[0.0, 0.0, 1.0]]),
                       tex_id=np.array([0]), texel=np.array([w / 7]),
                       **pack_textures([np.ones((8, 8, 3), dtype=np.float32)]))


def render_white(sim: dict, data_dir: str | Path, out_png: str | Path) -> None:
    """The white image of the simulated camera, as Raytrix ships one with a calibration:
    a uniformly white scene through the same MLA, aperture and vignetting, without noise
    (a white image is the mean of many frames), quantised like the shots. Dividing a
    shot by it removes the main lens's falloff (flat field). ``sim``: partial or whole."""
    sim = with_defaults("simulate", sim)
    data_dir = Path(data_dir)
    optics = optics_from_truth(data_dir / "truth" / "optics.json")
    calib = read_calib(data_dir / "calib.xml")
    lens_map = nearest_lens_map(MicrolensGrid(calib, optics.width, optics.height))
    sensor = sensor_truth(sim)
    img = _trace_shot(sim, optics, white_scene(), lens_map, lens_type_map(calib, lens_map),
                      np.eye(4), sensor)
    write_image(out_png, read_out(img, np.random.default_rng(0), 0.0, None,
                                  sensor["bit_depth"]))


def _shot_setup(sim: dict, optics: PlenopticOptics, scene: SceneArrays, lens_map: np.ndarray,
                types: np.ndarray, sensor: dict) -> tuple[LensletSetup, np.ndarray | None]:
    """What every shot of the camera traces with: the tracer's set-up
    (:func:`plenocal.simulate.raytrace.prepare_lenslet`) and the cos^4 falloff (None:
    off)."""
    setup = prepare_lenslet(scene, optics, lens_map, sim["render"]["samples"], sim["seed"],
                            lens_types=types)
    return setup, natural_vignetting(optics, lens_map) if sensor["vignetting_cos4"] else None


def _trace_prepared(setup: LensletSetup, falloff: np.ndarray | None, scene: SceneArrays,
                    cam_to_world: np.ndarray, sensor: dict) -> np.ndarray:
    """Trace one lenslet image with a prepared set-up (:func:`_shot_setup`) and the
    block's front stop."""
    stop = sensor["front_stop_distance_m"]
    img = trace_lenslet(setup, scene, cam_to_world, stop_distance=stop,
                        stop_diameter=sensor["front_stop_diameter_scale"]
                        * (2 * setup.half_aperture) if stop > 0 else 0.0)
    if falloff is not None:
        img = img * falloff[..., None]
    return img


def _trace_shot(sim: dict, optics: PlenopticOptics, scene: SceneArrays, lens_map: np.ndarray,
                types: np.ndarray, cam_to_world: np.ndarray, sensor: dict) -> np.ndarray:
    """Trace one lenslet image with the block's rays, front stop and cos^4 falloff."""
    return _trace_prepared(*_shot_setup(sim, optics, scene, lens_map, types, sensor), scene,
                           cam_to_world, sensor)


def render_shots(sim: dict, data_dir: str | Path, cams: list[str], out_pngs: list,
                 log=print) -> None:
    """Render the lenslet images of the shots ``cams`` into ``out_pngs`` (one each, in
    order): 8-bit RGB, or 12-bit data in a 16-bit PNG (``sensor.bit_depth``), with the
    vignetting and noise of the ``simulate`` block (partial or whole). The scene, the
    optics and the lens maps are set up once for all of them (about 1.3 s a job when
    each shot had its own); each shot's noise is seeded by its place among the dataset's
    shots, so an image does not depend on which shots are rendered with it. The tracing
    runs on numba's threads (``numba.set_num_threads``), pixel by pixel independently:
    the same bits on any number of threads."""
    if len(cams) != len(out_pngs):
        raise ValueError(f"{len(cams)} shots but {len(out_pngs)} output paths")
    sim = with_defaults("simulate", sim)
    data_dir = Path(data_dir)
    optics = optics_from_truth(data_dir / "truth" / "optics.json")
    shots = read_json(data_dir / "truth" / "shots.json")
    unknown = [c for c in cams if c not in shots]
    if unknown:
        raise KeyError(f"{', '.join(unknown)}: not shots of this dataset "
                       f"({data_dir / 'truth' / 'shots.json'} has {', '.join(sorted(shots))})")
    scene = scene_arrays(read_json(data_dir / "truth" / "scene.json"))
    calib = read_calib(data_dir / "calib.xml")
    grid = MicrolensGrid(calib, optics.width, optics.height)
    lens_map = nearest_lens_map(grid)
    types = lens_type_map(calib, lens_map)
    sensor = sensor_truth(sim)
    order = sorted(shots)
    # what every shot traces with, once (0.1 s a shot on the default camera)
    setup, falloff = _shot_setup(sim, optics, scene, lens_map, types, sensor)

    def finish(cam: str, img: np.ndarray, out_png) -> None:
        rng = np.random.default_rng([sim["seed"], 5, order.index(cam)])
        write_image(out_png, read_out(img, rng, sensor["noise_std"], sensor["full_well_e"],
                                      sensor["bit_depth"]), level=LENSLET_PNG_LEVEL)
        log(f"{cam}: done")

    # each shot's readout and PNG (single-threaded, 0.25 s on the default camera) beside
    # the next shot's tracing, so that no core waits for them
    with ThreadPoolExecutor(max_workers=1) as writer:
        pending = None
        for k, (cam, out_png) in enumerate(zip(cams, out_pngs, strict=True)):
            log(f"{cam}: tracing {optics.width}x{optics.height} px x "
                f"{sim['render']['samples']} rays ({optics.lens_types} lens type(s), "
                f"{optics.kind}), shot {k + 1} of {len(cams)}")
            img = _trace_prepared(setup, falloff, scene, np.asarray(shots[cam]["cam_to_world"]),
                                  sensor)
            if pending is not None:
                pending.result()  # (raises the writer's error here)
            pending = writer.submit(finish, cam, img, out_png)
        if pending is not None:
            pending.result()


def render_shot(sim: dict, data_dir: str | Path, cam: str, out_png: str | Path,
                log=print) -> None:
    """Render the lenslet image of shot ``cam`` into ``out_png`` (:func:`render_shots`)."""
    render_shots(sim, data_dir, [cam], [out_png], log=log)
