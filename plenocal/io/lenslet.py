"""The lenslet folder of a real capture, ``data/<dataset>/lenslet/``: its shots, each a
lenslet image or a raw YUV 4:2:0 recording with the frame to calibrate on.

A shot is ``<shot>.png`` (``x<col>_y<row>.png``, ``hand<k>.png``: the image the converter
reads) or ``<shot>[_<suffix>].yuv``, a recording of the camera (``x00_y00.yuv``,
``x00_y00_3976x2956_30fps_10bit.yuv``): its frame ``datasets.<d>.video.frame`` (one index
for every recording, or one per shot) is extracted by rule ``lenslet_frame`` into
``results/<d>/lenslet/<shot>.png``, the RGB image that ``plenocal convert`` makes
of a frame (:func:`plenocal.convert.video.lenslet_frame`: 8-bit from an 8-bit recording,
else 16-bit, converted with 16 significant bits). The frame's size and bit depth come
from the file's name (MPEG style, :func:`plenocal.io.yuv.parse_name`) or from
``video.size`` / ``video.bit_depth``; its colour from ``video.matrix`` / ``video.range``
(the command line's defaults).

:func:`scan_lenslet_folder` reads the folder and checks it before any job (file names,
one file a shot, the recordings' sizes, the frame index, the frame's size against the
datasheet's sensor), stat only; :func:`check_capture` then what the workflow needs of the
shots (the array's grid, the hand-held shots; each PNG's header, size, format and end; all
shots grey or all colour; no shot a copy of another): a :class:`CaptureError` names the
file, the config key and the remedy.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from plenocal import names
from plenocal.io import png

if TYPE_CHECKING:
    import numpy as np

    from plenocal.io.yuv import YuvFormat

# plenocal.io.yuv (numpy, cv2) is imported where a recording is read: the workflow scans
# a capture of PNGs when it parses its rules, and imports neither for it (issue 15: the
# no-op's time)

#: a recording's name: the shot's, then ``_`` and anything (the MPEG-style size, rate and
#: bit depth), ``.yuv``
_VIDEO_NAME = re.compile(rf"({names.SHOT_PATTERN})(?:_(.*))?\.yuv", re.DOTALL)
_SIZE = re.compile(r"([1-9][0-9]*)x([1-9][0-9]*)")


class CaptureError(ValueError):
    """A real capture's lenslet folder or video settings that the workflow cannot read
    (the file, the key and the remedy in the message)."""


@dataclass(frozen=True)
class VideoShot:
    """A shot given as a raw YUV recording: the frame to calibrate on and how to read it."""

    path: Path
    fmt: YuvFormat
    frame: int
    frames: int  # in the file
    matrix: str
    range: str

    def params(self) -> dict:
        """What rule ``lenslet_frame`` reads (its params: a change reruns the extraction)."""
        return {"frame": self.frame, "size": [self.fmt.width, self.fmt.height],
                "bit_depth": self.fmt.bits, "matrix": self.matrix, "range": self.range}


def video_shot_from_params(path: str | Path, params: dict) -> VideoShot:
    """The :class:`VideoShot` of :meth:`VideoShot.params` (rule ``lenslet_frame``)."""
    from plenocal.io.yuv import YuvFormat  # noqa: PLC0415 - see the imports
    fmt = YuvFormat(int(params["size"][0]), int(params["size"][1]), int(params["bit_depth"]))
    return VideoShot(Path(path), fmt, int(params["frame"]), -1, str(params["matrix"]),
                     str(params["range"]))


def extract_frame(shot: VideoShot) -> np.ndarray:
    """The shot's frame as the RGB lenslet image the converter reads
    (:func:`plenocal.convert.video.lenslet_frame`: 8-bit from an 8-bit recording, else
    16-bit, to convert with 16 significant bits)."""
    from plenocal.convert.video import lenslet_frame  # noqa: PLC0415 - see the imports
    from plenocal.io.yuv import read_frame  # noqa: PLC0415

    planes = read_frame(shot.path, shot.fmt, shot.frame)
    return lenslet_frame(planes, shot.fmt.bits, shot.matrix, shot.range)


def _bad_names(entries: list[Path]) -> list[str]:
    bad = []
    for p in entries:
        if p.is_dir():
            bad.append(f"{p.name}/ (a folder)")
        elif p.suffix == ".png":
            if not names.is_shot(p.stem):
                bad.append(p.name)
        elif p.suffix == ".yuv":
            if not _VIDEO_NAME.fullmatch(p.name):
                bad.append(p.name)
        elif p.suffix.lower() in (".png", ".yuv"):
            bad.append(f"{p.name} (rename it to {p.suffix.lower()})")
        else:
            bad.append(p.name)
    return bad


def _video_format(path: Path, video: dict, key: str) -> YuvFormat:
    """The recording's format: its name's size and bit depth, or the config's (which must
    agree with the name where both give one)."""
    from plenocal.io.yuv import YuvError, YuvFormat, parse_name  # noqa: PLC0415
    named_size, named_bits = parse_name(path)
    size = None
    if video.get("size") is not None:
        m = _SIZE.fullmatch(str(video["size"]))
        if not m:
            raise CaptureError(f"config: {key}.size = {video['size']!r}: write it as WxH in "
                               "pixels, e.g. 3976x2956")
        size = (int(m.group(1)), int(m.group(2)))
    bits = video.get("bit_depth")
    for what, named, given, sub in (("size", named_size, size, "size"),
                                    ("bit depth", named_bits, bits, "bit_depth")):
        if named is not None and given is not None and named != given:
            shown = f"{named[0]}x{named[1]}" if sub == "size" else f"{named} bits"
            raise CaptureError(
                f"{path}: its name gives the {what} {shown}, but {key}.{sub} = "
                f"{video[sub]!r}: correct or remove {key}.{sub} (it is for recordings whose "
                "name does not give it), or rename the file")
    size, bits = size or named_size, bits or named_bits
    missing = [f"{what} ({key}.{sub}: {example})" for what, v, sub, example in
               (("frame size", size, "size", "WxH, e.g. 3976x2956"),
                ("bit depth", bits, "bit_depth", "8 or 10")) if v is None]
    if missing:
        raise CaptureError(
            f"{path}: the {' and the '.join(missing)} of this raw YUV 4:2:0 recording "
            f"{'are' if len(missing) > 1 else 'is'} neither in its name nor in config.yaml: "
            "give it there, or name the file MPEG-style, e.g. x00_y00_3976x2956_30fps_10bit.yuv")
    try:
        return YuvFormat(size[0], size[1], int(bits))  # type: ignore[index]
    except YuvError as exc:
        raise CaptureError(f"{path}: {exc}") from None


def _frame_index(shot: str, path: Path, video: dict, key: str, shots: list[str]) -> int:
    frame = video["frame"]
    if isinstance(frame, dict):
        if shot not in frame:
            raise CaptureError(
                f"config: {key}.frame names no frame for {shot} ({path.name}): give one for "
                f"every shot given as a video ({', '.join(shots)}), or one number for all")
        return int(frame[shot])
    return int(frame)


#: why a capture needs hand-held shots, said by the workflow's check before any job
#: (:func:`check_capture_shots`) and by registration A
#: (:func:`plenocal.calib.reg_a.sfm.check_shots`)
HANDHELD_WHY = ("the focal length is undetermined - it trades off against depth at a tiny "
                "reprojection error (Section II-B of the paper). Add a few shots taken by "
                "hand with rotations of several degrees")


def sensor_mismatch(path: str | Path, size: tuple[int, int],
                    sensor_size: tuple[int, int]) -> str:
    """The message for a shot of ``size`` (width, height) where camera.yaml's sensor is
    ``sensor_size``: said before any job (:func:`check_capture`) and by the conversion
    (:func:`plenocal.convert.shot.load_lenslet`)."""
    return (f"{path}: the image is {size[0]}x{size[1]} pixels but camera.yaml says the "
            f"sensor is {sensor_size[0]}x{sensor_size[1]}: every shot is one sensor readout "
            "of that size (for a crop, give camera.yaml's sensor_width_px / sensor_height_px "
            "the crop's size and calib.xml its offset moved with the crop)")


def png_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of a PNG from its IHDR chunk (the file's first 24 bytes), without
    decoding it. Raises :class:`CaptureError` naming the file where it is no PNG (an
    empty file, a copy cut short, another format named .png)."""
    with open(path, "rb") as fh:
        size = png.header_size(fh.read(png.HEADER_BYTES))
    if size is None:
        raise CaptureError(f"{path}: not a PNG image (its first bytes are not a PNG's "
                           "signature and header; an empty file, a copy cut short, or another "
                           "format renamed): put the lenslet image there as a PNG")
    return size


def png_format(path: str | Path) -> tuple[int, int]:
    """(bit depth, colour type) of a PNG from its IHDR chunk; CaptureError naming the file
    where it is a palette image or of fewer than 8 bits a sample, which no camera's
    readout is and the converter would read as it decodes them (quantised levels)."""
    with open(path, "rb") as fh:
        fmt = png.header_format(fh.read(png.FORMAT_BYTES))
    if fmt is None:
        raise CaptureError(f"{path}: not a PNG image (no PNG header): put the lenslet image "
                           "there as a PNG")
    depth, kind = fmt
    if kind == png.PALETTE or depth < 8:
        what = "a palette image" if kind == png.PALETTE else f"{depth}-bit samples"
        raise CaptureError(f"{path}: {what}, not the camera's readout: save the lenslet "
                           "image as an 8- or 16-bit grey or RGB PNG, as the camera gave it")
    return depth, kind


def _colour(kind: int) -> bool:
    """Whether the converter reads a PNG of colour type ``kind`` as colour: RGB, with or
    without alpha, and grey with alpha, which OpenCV decodes to three channels."""
    return kind in (png.RGB, png.RGB_ALPHA, png.GREY_ALPHA)


def check_one_format(kinds: dict[str, bool], folder: str | Path) -> None:
    """CaptureError where some shots are colour and others grey (``kinds``: shot -> colour):
    one camera gives every shot alike (a raw Bayer frame grey, which ``convert.bayer``
    demosaics for every shot; a demosaiced one in colour), and a grey shot among colour
    ones converts to grey views that the synthesis scores 4-11 dB down, without a word."""
    colour = sorted(s for s, c in kinds.items() if c)
    grey = sorted(s for s, c in kinds.items() if not c)
    if not colour or not grey:
        return
    odd, odd_kind, rest_kind = ((grey, "grey", "colour") if len(grey) <= len(colour)
                                else (colour, "colour (RGB)", "grey"))
    shown = ", ".join(odd[:8]) + (f" and {len(odd) - 8} more" if len(odd) > 8 else "")
    raise CaptureError(
        f"{folder}/: {shown} {'is' if len(odd) == 1 else 'are'} {odd_kind}, the other "
        f"{len(kinds) - len(odd)} shots {rest_kind}: one camera gives every shot alike (a raw "
        "Bayer frame grey, which convert.bayer demosaics for every shot; a demosaiced one "
        f"in colour): save {'it' if len(odd) == 1 else 'them'} as the others are")


def _samples(path: Path, size: int, block: int = 1 << 16) -> bytes:
    """Four blocks of the file (start, thirds, end): enough to tell two recordings apart."""
    out = []
    with open(path, "rb") as fh:
        for at in (0, size // 3, 2 * size // 3, max(0, size - block)):
            fh.seek(at)
            out.append(fh.read(block))
    return b"".join(out)


def fingerprint(path: str | Path) -> str:
    """``<size>:<hash>`` of a capture's file from its size and four 64-kB blocks (start,
    thirds, end; a few milliseconds however large the file): the conversions' params on a
    real capture, so that a shot replaced by a file whose time stamp is older than the
    views (``cp -p``, ``rsync -a``, an unpacked archive) is converted again, where
    Snakemake, which compares time stamps, would keep the old views. The same bytes keep
    their fingerprint: it adds no rerun of its own (a newer time stamp, ``cp`` or ``touch``,
    reruns the conversion as Snakemake always did; ``mv``, ``cp -p`` or ``rsync -a`` of the
    same files nothing). Read once a process for a file as it stands (the workflow asks for
    it in :func:`check_no_copies` and for each job's params)."""
    st = Path(path).stat()
    return _fingerprint(str(path), st.st_size, st.st_mtime_ns)


@functools.cache
def _fingerprint(path: str, size: int, mtime_ns: int) -> str:
    import hashlib  # noqa: PLC0415

    return f"{size}:{hashlib.sha256(_samples(Path(path), size)).hexdigest()[:16]}"


def _same_bytes(a: Path, b: Path, chunk: int = 1 << 22) -> bool:
    with open(a, "rb") as fa, open(b, "rb") as fb:
        while True:
            x, y = fa.read(chunk), fb.read(chunk)
            if x != y:
                return False
            if not x:
                return True


def check_no_copies(files: dict[str, Path], folder: str | Path,
                    frames: dict[str, int] | None = None) -> None:
    """CaptureError where two shots are the same file's bytes (a copy under a second
    name): registration A would place the two shots on one spot, and the run's warnings
    would blame the scale or the datasheet. Only files of one :func:`fingerprint` (size
    and sampled blocks) are read in full. ``frames``: the frame each recording gives
    (shots that take other frames of one recording, such as hand-held shots from one
    video, are not copies)."""
    frames = frames or {}
    seen: dict[tuple[str, int | None], str] = {}
    for shot in sorted(files):
        first = seen.setdefault((fingerprint(files[shot]), frames.get(shot)), shot)
        if first != shot and _same_bytes(files[first], files[shot]):
            raise CaptureError(
                f"{folder}/: {files[shot].name} holds the same bytes as "
                f"{files[first].name}: a copy, not a shot of its own (registration A "
                f"would put {shot} where {first} is); put {shot}'s own lenslet image "
                "there")


def check_capture_shots(shots: list[str], dataset: str, folder: str | Path) -> None:
    """The shots a capture needs (before any job runs): array shots ``x<col>_y<row>``
    forming the whole grid from ``x00_y00`` (the array's layout is read from their numbers:
    the synthesis experiments take its corners and middle shot, and the rig its columns
    and rows), and hand-held shots, without which registration A cannot fix the focal
    length (Section II-B). Raises :class:`CaptureError` naming what is missing."""
    folder = Path(folder)
    pos = {names.array_position(s) for s in shots if names.is_array_shot(s)}
    if not pos:
        raise CaptureError(
            f"dataset {dataset!r}: {folder}/ holds no array shot: name the array's lenslet "
            "images x<col>_y<row>.png from x00_y00 (README, 'Bringing a real capture')")
    cols = max(c for c, _ in pos) + 1
    rows = max(r for _, r in pos) + 1
    missing = [names.array_shot(c, r) for r in range(rows) for c in range(cols)
               if (c, r) not in pos]
    if missing:
        shown = ", ".join(missing[:8]) + (f" and {len(missing) - 8} more"
                                          if len(missing) > 8 else "")
        raise CaptureError(
            f"dataset {dataset!r}: the array shots in {folder}/ do not fill a {cols} x {rows} "
            f"grid from x00_y00: {shown} missing. Number the columns and rows from 00 "
            "without gaps (x<col>_y<row>: the array's layout is read from the numbers)")
    if not any(names.is_handheld_shot(s) for s in shots):
        raise CaptureError(
            f"dataset {dataset!r}: {folder}/ holds no hand-held shot (hand00.png, ...): "
            f"registration A needs them, as with the parallel array alone {HANDHELD_WHY} "
            "(README, 'Bringing a real capture')")


def check_capture(sources: dict[str, Path | VideoShot], dataset: str, folder: str | Path,
                  sensor_size: tuple[int, int]) -> None:
    """What the workflow needs of a capture's shots (:func:`scan_lenslet_folder`'s
    ``sources``), checked before any job: the shots (:func:`check_capture_shots`); every
    PNG a PNG (its header read) of camera.yaml's sensor size ``(width, height)``, as the
    recordings' frames are, of 8 or 16 bits a sample and no palette (:func:`png_format`;
    alpha allowed) and whole (:func:`plenocal.io.png.truncation`); all shots grey or all
    colour as the converter reads them (:func:`check_one_format`); no shot a copy of
    another (:func:`check_no_copies`; a recording's other frame is no copy).
    Raises :class:`CaptureError` naming the file."""
    check_capture_shots(list(sources), dataset, folder)
    colour: dict[str, bool] = {}
    for shot, path in sources.items():
        if isinstance(path, VideoShot):
            colour[shot] = True  # a YUV 4:2:0 recording's frame is RGB
            continue
        size = png_size(path)
        if size != tuple(sensor_size):
            raise CaptureError(sensor_mismatch(path, size, sensor_size))
        colour[shot] = _colour(png_format(path)[1])
        cut = png.truncation(path)  # its last 12 bytes, where it is whole
        if cut is not None:
            raise CaptureError(f"{path}: a truncated PNG, {cut}: the file was not copied "
                               "whole; copy it again")
    check_one_format(colour, folder)
    check_no_copies({s: p.path if isinstance(p, VideoShot) else p
                     for s, p in sources.items()}, folder,
                    {s: p.frame for s, p in sources.items() if isinstance(p, VideoShot)})


#: what a simulated dataset's rules write into ``data/<dataset>/`` (rules/simulate.smk),
#: and the file whose presence says the simulator wrote them
SIMULATED_FILES = ("calib.xml", "camera.yaml", "lenslet")
SIMULATOR_MARK = Path("truth") / "scene.json"


def check_simulated_folder(folder: str | Path, dataset: str,
                           written_by_simulator: Callable[[Path], bool] | None = None
                           ) -> None:
    """A dataset with a ``simulate`` block is generated into ``folder`` (``data/<d>/``):
    CaptureError where ``folder`` already holds a capture's files there (calib.xml,
    camera.yaml or lenslet images) that the simulator did not write (no ``truth/scene.json``
    beside them, and ``written_by_simulator``, the workflow's own record of the job that
    wrote a file, does not name the simulator for calib.xml), which its rules would
    overwrite. A simulated dataset whose ``truth/`` was deleted is made again."""
    folder = Path(folder)
    if (folder / SIMULATOR_MARK).is_file():
        return
    calib = folder / "calib.xml"
    if written_by_simulator is not None and calib.is_file() and written_by_simulator(calib):
        return
    found = [name for name in SIMULATED_FILES if (folder / name).exists()
             and not ((folder / name).is_dir() and not any((folder / name).iterdir()))]
    if found:
        raise CaptureError(
            f"dataset {dataset!r} has a 'simulate' block, so the simulator writes "
            f"{folder}/, but {folder}/ already holds {', '.join(found)} that the simulator "
            f"did not write (no {SIMULATOR_MARK} beside them): a real capture's files, which "
            f"a run would overwrite. Remove the 'simulate' block from datasets.{dataset} to "
            "calibrate that capture, or give the simulated dataset another name; to have "
            f"a simulation made again, delete {folder}/ yourself")


def scan_lenslet_folder(folder: str | Path, dataset: str, video: dict | None,
                        sensor_size: tuple[int, int] | None = None
                        ) -> dict[str, Path | VideoShot]:
    """{shot: its PNG, or its :class:`VideoShot`} of a real capture's ``lenslet/``, in
    name order, checked as the module docstring says. ``video``: the dataset's
    ``video`` block (``None``: none in config.yaml); ``sensor_size``: (width, height) of
    camera.yaml's sensor, which every recording's frame must have."""
    folder = Path(folder)
    key = f"datasets.{dataset}.video"
    if not folder.is_dir():
        raise CaptureError(
            f"dataset {dataset!r}: {folder}/ does not exist; put the lenslet images "
            "there (x00_y00.png ... and hand00.png ..., or recordings x00_y00_<W>x<H>_"
            "<b>bit.yuv ...; README, 'Bringing a real capture'). A simulated dataset "
            "instead has a 'simulate' block, and its files are written there")
    entries = sorted(p for p in folder.iterdir() if not p.name.startswith("."))
    dangling = [p for p in entries if p.is_symlink() and not p.exists()]
    if dangling:
        raise CaptureError(
            f"dataset {dataset!r}: {', '.join(p.name for p in dangling)} in {folder}/ "
            f"{'is a link' if len(dangling) == 1 else 'are links'} to no file ("
            + ", ".join(str(p.readlink()) for p in dangling)
            + "): mount or copy what the link points to, or link the shot again")
    bad = _bad_names(entries)
    if bad:
        raise CaptureError(
            f"dataset {dataset!r}: {folder}/ may hold only lenslet images named "
            "x<col>_y<row>.png or hand<k>.png (two-digit numbers, lower-case .png) and "
            "recordings named as a shot, optionally followed by _ and the size and bit "
            f"depth (x00_y00_3976x2956_10bit.yuv); move or rename {', '.join(bad)}")
    files: dict[str, list[Path]] = {}
    for p in entries:
        shot = p.stem if p.suffix == ".png" else _VIDEO_NAME.fullmatch(p.name).group(1)
        files.setdefault(shot, []).append(p)
    twice = {s: ps for s, ps in files.items() if len(ps) > 1}
    if twice:
        s, ps = next(iter(twice.items()))
        raise CaptureError(
            f"dataset {dataset!r}: {' and '.join(p.name for p in ps)} in {folder}/ are "
            f"{'both' if len(ps) == 2 else 'all'} the shot {s}: keep one (a PNG is converted "
            f"as it is; from a .yuv recording the frame {key}.frame is extracted into "
            f"results/{dataset}/lenslet/{s}.png)"
            + (f"; also {', '.join(sorted(twice)[1:])}" if len(twice) > 1 else ""))
    if not files:
        raise CaptureError(f"dataset {dataset!r}: {folder}/ holds no lenslet image")
    videos = [s for s, (p,) in files.items() if p.suffix == ".yuv"]
    if videos and video is None:
        raise CaptureError(
            f"dataset {dataset!r}: {files[videos[0]][0]} is a video recording: give the frame "
            f"to calibrate on in config.yaml, {key}: {{frame: K}} (K from 0; README, "
            "'Bringing a real capture')")
    if video is not None and not videos:
        raise CaptureError(
            f"config: {key} is set, but {folder}/ holds no .yuv recording: remove {key}, or "
            "put the recordings there (<shot>_<W>x<H>_<b>bit.yuv)")
    if video is not None and isinstance(video.get("frame"), dict):
        extra = sorted(set(video["frame"]) - set(videos))
        if extra:
            raise CaptureError(
                f"config: {key}.frame names {', '.join(extra)}, which {folder}/ holds no "
                f".yuv recording of (recordings: {', '.join(videos)}): remove or rename "
                "the key")
    out: dict[str, Path | VideoShot] = {}
    for shot, (path,) in files.items():
        if path.suffix == ".png":
            out[shot] = path
            continue
        assert video is not None
        fmt = _video_format(path, video, key)
        nbytes = path.stat().st_size
        if nbytes == 0 or nbytes % fmt.frame_bytes:
            raise CaptureError(
                f"{path}: {nbytes} bytes is not a whole number of {fmt.width}x{fmt.height} "
                f"{fmt.bits}-bit YUV 4:2:0 frames ({fmt.frame_bytes} bytes each, "
                f"{nbytes / fmt.frame_bytes:.3f} frames): a wrong size or bit depth (in the "
                f"name, or {key}.size / bit_depth), or a recording cut short")
        count = nbytes // fmt.frame_bytes
        frame = _frame_index(shot, path, video, key, videos)
        if frame >= count:
            sub = f"frame.{shot}" if isinstance(video["frame"], dict) else "frame"
            raise CaptureError(
                f"config: {key}.{sub} = {frame}: {path} holds {count} frame"
                f"{'s' if count != 1 else ''} (0..{count - 1}): give an index below {count}")
        from plenocal.io.yuv import YuvError, probe_depth  # noqa: PLC0415 - see the imports

        try:  # 10-bit words named 8bit (or the other way) can be a whole number of frames
            probe_depth(path, fmt, frame, f"Check the bit depth in its name or {key}.bit_depth")
        except YuvError as exc:
            raise CaptureError(str(exc)) from None
        if sensor_size is not None and (fmt.width, fmt.height) != tuple(sensor_size):
            raise CaptureError(
                f"{path}: its frames are {fmt.width}x{fmt.height} pixels but camera.yaml "
                f"says the sensor is {sensor_size[0]}x{sensor_size[1]}: every frame is one "
                "sensor readout of that size (correct the size in the name, "
                f"{key}.size or camera.yaml; for a crop, give camera.yaml's "
                "sensor_width_px / sensor_height_px the crop's size and calib.xml its offset "
                "moved with the crop)")
        out[shot] = VideoShot(path, fmt, frame, count, video["matrix"], video["range"])
    return dict(sorted(out.items()))
