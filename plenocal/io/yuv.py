"""Raw YUV 4:2:0 video (planar I420), as the MPEG lenslet sequences, RVS and TMIV use it.

Layout of one frame of ``W x H`` (what RVS 4.0's ``read_color_YUV`` reads): the luma plane
``H x W``, then Cb and Cr, each ``H/2 x W/2`` (rounded down), one sample per byte for 8-bit
video and one little-endian 16-bit word per sample for 9-16 bits (``yuv420p10le``: the 10
bits LSB-aligned). Frame ``k`` starts at byte ``k x frame_bytes``; no header.

MPEG names its files after what is in them, ``Boys2_3976x2956_30fps_8bit.yuv``,
``v3_texture_1920x1080_yuv420p10le.yuv``: :func:`parse_name` reads the size and the bit
depth from such a name, :func:`mpeg_name` writes one.

Colour (:func:`yuv_to_rgb`, :func:`rgb_to_yuv`): ``matrix`` ``bt709`` (the default: MPEG's
usual for these sequences), ``bt601`` or ``bt2020`` (non-constant luminance); ``range``
``limited`` (the default: luma 16..235 and chroma 16..240, scaled by ``2^(bits-8)``) or
``full``. Chroma is upsampled by bilinear interpolation with the samples centred between
their two luma rows and columns (``cv2.resize``), and downsampled by the mean of each 2 x 2
block: the same siting both ways.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import cv2
import numpy as np

#: luma and blue-difference weights (Kr, Kb) of each colour matrix
MATRICES: dict[str, tuple[float, float]] = {
    "bt709": (0.2126, 0.0722),
    "bt601": (0.299, 0.114),
    "bt2020": (0.2627, 0.0593),
}
RANGES = ("limited", "full")
DEFAULT_MATRIX = "bt709"
DEFAULT_RANGE = "limited"


class YuvError(ValueError):
    """A YUV file that cannot be read as asked (its name and the remedy in the message)."""


@dataclass(frozen=True)
class YuvFormat:
    """Size and sample depth of a planar YUV 4:2:0 video."""

    width: int
    height: int
    bits: int

    def __post_init__(self) -> None:
        if self.width < 2 or self.height < 2:
            raise YuvError(f"YUV frame size {self.width}x{self.height}: need at least 2x2")
        if not 8 <= self.bits <= 16:
            raise YuvError(f"YUV bit depth {self.bits}: need 8..16")

    @property
    def chroma_size(self) -> tuple[int, int]:
        """(width, height) of each chroma plane: half the luma's, rounded down (RVS)."""
        return self.width // 2, self.height // 2

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint8) if self.bits == 8 else np.dtype("<u2")

    @property
    def frame_samples(self) -> int:
        cw, ch = self.chroma_size
        return self.width * self.height + 2 * cw * ch

    @property
    def frame_bytes(self) -> int:
        return self.frame_samples * self.dtype.itemsize

    @property
    def pix_fmt(self) -> str:
        """FFmpeg's name of the format: ``yuv420p``, ``yuv420p10le``, ..."""
        return "yuv420p" if self.bits == 8 else f"yuv420p{self.bits}le"


_SIZE = re.compile(r"(?<![0-9])([0-9]{2,5})x([0-9]{2,5})(?![0-9])")
_BITS = re.compile(r"(?<![0-9a-z])([0-9]{1,2})[-_]?bits?(?![a-z])", re.IGNORECASE)
_PIXFMT = re.compile(r"yuv420p(?:([0-9]{1,2})(?:le))?(?![0-9a-z])", re.IGNORECASE)
#: pixel formats other than planar 4:2:0 little-endian that a name may state (FFmpeg's
#: names, and the bare subsampling with its ``p``): read as 4:2:0, a 4:4:4 file of 2 frames
#: passed for 4 frames of noise
_OTHER_PIXFMT = re.compile(
    r"(?<![0-9a-z])(?:yuva?(?:444|422|440|411|410)p?|(?:444|422|440|411|410)p|yuv420p[0-9]{1,2}be"
    r"|nv12|nv21|nv16|p010|p016|gray|rgb24|bgr24)(?:[0-9]{1,2})?(?:le|be)?(?![0-9a-z])",
    re.IGNORECASE)


def parse_name(path: str | Path) -> tuple[tuple[int, int] | None, int | None]:
    """((width, height) or None, bits or None) as an MPEG-style file name states them:
    ``<W>x<H>`` anywhere in the name; ``<b>bit`` (``8bit``, ``10bit``) or FFmpeg's pixel
    format (``yuv420p`` = 8 bits, ``yuv420p10le`` = 10). A name that states two different
    sizes or depths states neither (None)."""
    sizes, bits = name_states(path)
    return (sizes.pop() if len(sizes) == 1 else None), (bits.pop() if len(bits) == 1 else None)


def name_states(path: str | Path) -> tuple[set[tuple[int, int]], set[int]]:
    """Every (width, height) and every bit depth the file name of ``path`` states
    (:func:`parse_name` takes one of each)."""
    name = Path(path).name
    sizes = {(int(w), int(h)) for w, h in _SIZE.findall(name)}
    bits = {int(b) for b in _BITS.findall(name)}
    bits |= {int(b) if b else 8 for b in _PIXFMT.findall(name)}
    return sizes, bits


def resolve_format(path: str | Path, size: tuple[int, int] | None = None,
                   bits: int | None = None) -> YuvFormat:
    """The format of ``path``: ``size`` / ``bits`` where given (the command line's
    ``--size`` / ``--bit-depth``), else as its name states them. Raises :class:`YuvError`
    naming the file and the remedy where neither gives them, or where the file is not a
    whole number of frames of that format."""
    path = Path(path)
    other = _OTHER_PIXFMT.search(path.name)
    if other:
        raise YuvError(f"{path}: its name states the pixel format {other.group(0)}; plenocal "
                       "reads planar YUV 4:2:0 (yuv420p, yuv420p10le): convert the file first "
                       "(e.g. ffmpeg -pix_fmt yuv420p10le), or rename it if the name is wrong")
    named_size, named_bits = parse_name(path)
    if size is not None and named_size is not None and tuple(size) != named_size:
        raise YuvError(f"{path}: its name states {named_size[0]}x{named_size[1]}, --size says "
                       f"{size[0]}x{size[1]}: leave --size out, or rename the file")
    if bits is not None and named_bits is not None and bits != named_bits:
        raise YuvError(f"{path}: its name states {named_bits} bits, --bit-depth says {bits}: "
                       "leave --bit-depth out, or rename the file")
    size = size or named_size
    bits = bits or named_bits
    missing = [what for what, v in (("size (--size WxH)", size), ("bit depth (--bit-depth 8 "
                                    "or 10)", bits)) if v is None]
    sizes, depths = name_states(path)
    both = [f"{what} ({' and '.join(v)})" for what, v, given in (
        ("sizes", sorted(f"{w}x{h}" for w, h in sizes), size),
        ("bit depths", [str(b) for b in sorted(depths)], bits)) if len(v) > 1 and given is None]
    if both:
        raise YuvError(f"{path}: its name states two {' and two '.join(both)}: pass the right "
                       "one with --size / --bit-depth, or rename the file")
    if missing:
        raise YuvError(f"{path}: the {' and the '.join(missing)} of this raw YUV 4:2:0 file "
                       "is neither in its name nor given: pass it on the command line, or name "
                       "the file MPEG-style, e.g. Boys2_3976x2956_30fps_10bit.yuv or "
                       "clip_1920x1080_yuv420p10le.yuv")
    fmt = YuvFormat(int(size[0]), int(size[1]), int(bits))  # type: ignore[index]
    nbytes = path.stat().st_size
    if nbytes == 0 or nbytes % fmt.frame_bytes:
        odd = ""
        if fmt.width % 2 or fmt.height % 2:
            ceil_bytes = (fmt.width * fmt.height + 2 * (-(-fmt.width // 2)) * (-(-fmt.height // 2))
                          ) * fmt.dtype.itemsize
            if nbytes and nbytes % ceil_bytes == 0:
                odd = (f" It is a whole number ({nbytes // ceil_bytes}) of frames whose chroma "
                       "planes are rounded up, as FFmpeg writes odd sizes; this reader takes "
                       "RVS's layout (rounded down): crop the video to an even size first "
                       "(e.g. ffmpeg -vf crop=trunc(iw/2)*2:trunc(ih/2)*2).")
        raise YuvError(f"{path}: {nbytes} bytes is not a whole number of {fmt.width}x"
                       f"{fmt.height} {fmt.bits}-bit YUV 4:2:0 frames ({fmt.frame_bytes} bytes "
                       f"each, {nbytes / fmt.frame_bytes:.3f} frames): wrong size or bit depth? "
                       "Check --size and --bit-depth (or the WxH and bit depth in the name)."
                       + odd)
    return fmt


def frame_count(path: str | Path, fmt: YuvFormat) -> int:
    return Path(path).stat().st_size // fmt.frame_bytes


def read_frame(path: str | Path, fmt: YuvFormat, index: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame ``index`` (0-based) of ``path`` as its (Y, Cb, Cr) planes (uint8 or uint16)."""
    n = frame_count(path, fmt)
    if not 0 <= index < n:
        raise YuvError(f"{path}: no frame {index} (the file holds {n})")
    with open(path, "rb") as fh:
        fh.seek(index * fmt.frame_bytes)
        data = fh.read(fmt.frame_bytes)
    a = np.frombuffer(data, dtype=fmt.dtype).astype(fmt.dtype.newbyteorder("="), copy=False)
    check_depth(path, fmt, index, a)
    cw, ch = fmt.chroma_size
    ny, nc = fmt.width * fmt.height, cw * ch
    return (a[:ny].reshape(fmt.height, fmt.width), a[ny:ny + nc].reshape(ch, cw),
            a[ny + nc:].reshape(ch, cw))


#: the remedy :func:`check_depth` names by default: the command line's
DEPTH_REMEDY = "Check --bit-depth (or the bit depth in the name)"
#: luma samples :func:`probe_depth` reads from the middle of a frame
PROBE_SAMPLES = 1 << 16


def check_depth(path: str | Path, fmt: YuvFormat, index: int, samples: np.ndarray,
                remedy: str = DEPTH_REMEDY) -> None:
    """Raise :class:`YuvError` where frame ``index``'s ``samples`` (the whole frame as
    read, or luma samples from an even offset: :func:`probe_depth`) cannot be of ``fmt``'s
    bit depth: 9-15-bit samples at or over ``2^bits`` (8-bit data, or big-endian words, read
    as ``yuv420p<b>le``), or an 8-bit frame whose every second luma byte is at most 3 while
    others are not (little-endian 10-16-bit words read as bytes: no picture's luma is that
    dark in every other column). ``remedy``: what the message tells the user to check."""
    if 8 < fmt.bits < 16:
        top = int(samples.max())
        if top >= 1 << fmt.bits:
            raise YuvError(f"{path}: frame {index} holds samples up to {top}, which do not fit "
                           f"{fmt.bits} bits: is the file 8-bit, or big-endian? {remedy}")
    elif fmt.bits == 8:
        luma = samples[:fmt.width * fmt.height]
        high, low = luma[1::2], luma[0::2]
        if high.size and int(high.max()) <= 3 < int(low.max()):
            raise YuvError(f"{path}: frame {index} reads as 16-bit little-endian words (every "
                           "second byte is 0..3), not as 8-bit samples: is the file 10-bit? "
                           f"{remedy}")


def probe_depth(path: str | Path, fmt: YuvFormat, index: int,
                remedy: str = DEPTH_REMEDY) -> None:
    """:func:`check_depth` on :data:`PROBE_SAMPLES` luma samples from the middle rows of
    frame ``index`` (the frame's centre, where a lenslet image is lit): a start-up check
    that reads 64 K samples, not the whole frame."""
    start = (fmt.height // 2) * fmt.width  # an even sample offset: the byte pairs aligned
    count = min(PROBE_SAMPLES, fmt.width * fmt.height - start)
    with open(path, "rb") as fh:
        fh.seek(index * fmt.frame_bytes + start * fmt.dtype.itemsize)
        data = fh.read(count * fmt.dtype.itemsize)
    samples = np.frombuffer(data, dtype=fmt.dtype)
    check_depth(path, fmt, index, samples, remedy)


def write_frame(fh: BinaryIO, planes: tuple[np.ndarray, np.ndarray, np.ndarray],
                fmt: YuvFormat) -> None:
    """Append one frame (Y, Cb, Cr in the planes' sizes of ``fmt``) to an open file."""
    cw, ch = fmt.chroma_size
    shapes = ((fmt.height, fmt.width), (ch, cw), (ch, cw))
    for plane, shape in zip(planes, shapes, strict=True):
        if plane.shape != shape:
            raise YuvError(f"YUV plane of shape {plane.shape}, the format needs {shape}")
        fh.write(np.ascontiguousarray(plane, dtype=fmt.dtype).tobytes())


def mpeg_name(stem: str, fmt: YuvFormat) -> str:
    """``<stem>_<W>x<H>_<b>bit_<pix_fmt>.yuv``, e.g. ``v_2_2_1440x1064_10bit_yuv420p10le.yuv``
    (:func:`parse_name` reads it back; TMIV and the MPEG sequences name theirs this way)."""
    return f"{stem}_{fmt.width}x{fmt.height}_{fmt.bits}bit_{fmt.pix_fmt}.yuv"


def _coefficients(matrix: str) -> tuple[float, float, float]:
    if matrix not in MATRICES:
        raise YuvError(f"YUV colour matrix {matrix!r}: one of {', '.join(MATRICES)}")
    kr, kb = MATRICES[matrix]
    return kr, 1.0 - kr - kb, kb


def _levels(bits: int, rng: str) -> tuple[float, float, float, float]:
    """(luma black, luma span, chroma zero, chroma span) in code values."""
    if rng not in RANGES:
        raise YuvError(f"YUV range {rng!r}: one of {', '.join(RANGES)}")
    s = float(1 << (bits - 8))
    if rng == "limited":
        return 16.0 * s, 219.0 * s, 128.0 * s, 224.0 * s
    top = float((1 << bits) - 1)
    return 0.0, top, float(1 << (bits - 1)), top


def yuv_to_rgb(planes: tuple[np.ndarray, np.ndarray, np.ndarray], bits: int,
               matrix: str = DEFAULT_MATRIX, rng: str = DEFAULT_RANGE,
               rows: slice | None = None) -> np.ndarray:
    """RGB float32 (H, W, 3) in [0, 1] of one frame's (Y, Cb, Cr) planes (the module
    docstring: chroma upsampling, matrices and ranges). Values outside the RGB cube (the
    limited range's foot- and headroom, out-of-gamut chroma) are clipped. ``rows``: only
    those rows of the frame (a slice with step 1), the same numbers as those rows of the
    whole frame's (a frame of even size samples only the chroma rows they need)."""
    y, cb, cr = planes
    H, W = y.shape
    a, b, _ = (rows or slice(None)).indices(H)
    kr, kg, kb = _coefficients(matrix)
    black, yspan, zero, cspan = _levels(bits, rng)
    Y = (y[a:b].astype(np.float32) - np.float32(black)) * np.float32(1.0 / yspan)
    ch = cb.shape[0]
    # an exact 2x upsampling reads chroma rows (y + 0.5) / 2 - 0.5: a band from an even
    # row needs its own chroma rows and one on either side
    exact = H == 2 * ch and W == 2 * cb.shape[1] and a % 2 == 0
    lo, hi = (max(a // 2 - 1, 0), min((b + 1) // 2 + 1, ch)) if exact else (0, ch)
    top = a - 2 * lo if exact else a

    def chroma(p: np.ndarray) -> np.ndarray:
        c = (p[lo:hi].astype(np.float32) - np.float32(zero)) * np.float32(1.0 / cspan)
        # centred siting: output pixel x samples chroma at (x + 0.5) / 2 - 0.5, an exact 2x
        # upsampling; an odd size's last row or column repeats the one before it (resized
        # to the frame's size instead, the chroma drifted up to a pixel by the far edges)
        up = cv2.resize(c, (2 * c.shape[1], 2 * c.shape[0]), interpolation=cv2.INTER_LINEAR)
        short = (max(top + b - a - up.shape[0], 0), max(W - up.shape[1], 0))
        if any(short):
            up = np.pad(up, ((0, short[0]), (0, short[1])), mode="edge")
        return up[top:top + b - a, :W]

    Cb, Cr = chroma(cb), chroma(cr)
    R = Y + np.float32(2 * (1 - kr)) * Cr
    B = Y + np.float32(2 * (1 - kb)) * Cb
    G = Y - np.float32(2 * kb * (1 - kb) / kg) * Cb - np.float32(2 * kr * (1 - kr) / kg) * Cr
    return np.clip(np.dstack([R, G, B]), 0.0, 1.0)


def integer_rgb_to_yuv(view: np.ndarray, bits: int, matrix: str = DEFAULT_MATRIX,
                       rng: str = DEFAULT_RANGE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`rgb_to_yuv` of an 8- or 16-bit RGB image (H, W, 3) over its type's range
    (``view / 255`` or ``/ 65535`` in float32), the same planes in one compiled pass
    without a float copy (:mod:`plenocal.io.yuvkernels`)."""
    from plenocal.io.yuvkernels import view_to_yuv420  # noqa: PLC0415 (numba)

    if view.ndim != 3 or view.shape[2] != 3 or view.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"an 8- or 16-bit RGB image, not {view.dtype} {view.shape}")
    kr, kg, kb = _coefficients(matrix)
    black, yspan, zero, cspan = _levels(bits, rng)
    H, W = view.shape[:2]
    dtype = np.uint8 if bits == 8 else np.uint16
    planes = (np.empty((H, W), dtype), np.empty((H // 2, W // 2), dtype),
              np.empty((H // 2, W // 2), dtype))
    f = np.float32
    view_to_yuv420(np.ascontiguousarray(view), f(1.0 / np.iinfo(view.dtype).max), f(kr), f(kg),
                   f(kb), f(0.5 / (1 - kb)), f(0.5 / (1 - kr)), f(black), f(yspan), f(zero),
                   f(cspan), f((1 << bits) - 1), *planes)
    return planes


def rgb_to_yuv(rgb: np.ndarray, bits: int, matrix: str = DEFAULT_MATRIX,
               rng: str = DEFAULT_RANGE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Y, Cb, Cr) planes (uint8 for 8 bits, else uint16) of an RGB image (H, W, 3) in
    [0, 1] (float; clipped), chroma the mean of each 2 x 2 block (an odd last row or column
    is dropped from the chroma, as RVS reads it)."""
    kr, kg, kb = _coefficients(matrix)
    black, yspan, zero, cspan = _levels(bits, rng)
    rgb = np.clip(np.asarray(rgb, dtype=np.float32), 0.0, 1.0)
    R, G, B = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    Y = np.float32(kr) * R + np.float32(kg) * G + np.float32(kb) * B
    Cb = (B - Y) * np.float32(0.5 / (1 - kb))
    Cr = (R - Y) * np.float32(0.5 / (1 - kr))
    H, W = Y.shape
    h2, w2 = H // 2, W // 2

    def half(c: np.ndarray) -> np.ndarray:
        c = c[:2 * h2, :2 * w2]
        return 0.25 * (c[0::2, 0::2] + c[1::2, 0::2] + c[0::2, 1::2] + c[1::2, 1::2])

    top = (1 << bits) - 1
    dtype = np.uint8 if bits == 8 else np.uint16

    def code(v: np.ndarray, offset: float, span: float) -> np.ndarray:
        return np.clip(np.rint(v * np.float32(span) + np.float32(offset)), 0, top).astype(dtype)

    return (code(Y, black, yspan), code(half(Cb), zero, cspan), code(half(Cr), zero, cspan))
