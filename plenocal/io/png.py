"""PNG encoding for :func:`plenocal.io.files.write_image`: the file format written here, the
deflate stream by libdeflate (the ``deflate`` package).

A PNG (ISO/IEC 15948) is the 8-byte signature, an ``IHDR`` chunk (size, bit depth, colour
type), the filtered rows deflated as one zlib stream in ``IDAT`` chunks (one unless it
exceeds :data:`IDAT_BYTES`), and ``IEND``; each chunk carries its length and a CRC-32.
Only what the workflow writes is encoded: grey or RGB (colour types 0 and 2), 8 or 16 bits
(16-bit samples big-endian), no interlacing, no ancillary chunks (no time stamp: the same
pixels give the same bytes).

* ``level`` 0: stored (zlib's level 0, no compression), every row unfiltered (a filter only
  helps compression). For noisy 12-bit lenslet images that compress to 70 % at best.
* ``level`` 1-3: libdeflate's levels, every row with PNG's "up" filter (the difference to
  the row above). libdeflate compresses the whole buffer in one call, so its stream is a
  function of the rows, the level and its version alone. ISA-L's streaming deflate (the
  ``isal`` package, used before) once gave another, equally valid stream for the same
  rows of a ground-truth render in a workflow job (the CI's reproducibility test; not
  reproduced in 200 runs outside the workflow): that broke the promise of the same bytes
  for the same pixels. On a 1576 x 1190 RGB view (HandTools) libdeflate's level 1 takes
  25.5 ms for 2.37 MB, ISA-L's level 1 took 17.1 ms for 2.46 MB, zlib's Huffman-only level
  1 (what OpenCV's encoder was set to) 59 ms for 2.70 MB. libdeflate lets go of the GIL,
  so views are encoded on several threads at once.

Any PNG reader decodes these files (OpenCV's and Pillow's are tested, ``tests/test_png.py``).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: PNG colour type by channel count: grey, RGB
_COLOUR_TYPE = {1: 0, 3: 2}
_FILTER_NONE, _FILTER_UP = 0, 2
LEVELS = (0, 1, 2, 3)
#: bytes of deflated data per IDAT chunk (a chunk holds at most 2^31 - 1; the zlib stream
#: may be cut anywhere between chunks)
IDAT_BYTES = 1 << 30

#: bits per sample of the PNG views ``plenocal convert`` writes, unless ``--png-bits`` says
#: 16: what every image tool reads (Pillow, which NeRF and Gaussian-splatting loaders use,
#: reads 16-bit colour PNGs as 8-bit)
VIEW_BITS = 8
#: the bits per sample a PNG view may have
VIEW_BITS_CHOICES = (8, 16)


def view_dtype(bits: int | None) -> type:
    """The sample type of PNG views of ``bits`` bits per sample (None: :data:`VIEW_BITS`)."""
    bits = VIEW_BITS if bits is None else bits
    if bits not in VIEW_BITS_CHOICES:
        raise ValueError(f"PNG views hold 8 or 16 bits per sample, not {bits}")
    return np.uint8 if bits == 8 else np.uint16


def chunk(kind: bytes, data: bytes | memoryview) -> list[bytes | memoryview]:
    """One PNG chunk as its parts, to be joined once with the others: length, type, data
    (not copied), CRC-32 of type and data."""
    return [struct.pack(">I", len(data)), kind, data,
            struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))]


def filtered_rows(image: np.ndarray, up: bool) -> np.ndarray:
    """(H, 1 + W * C * bytes) uint8: each row's filter byte and its samples (16-bit ones
    big-endian), with the "up" filter (bytes minus those of the row above, modulo 256;
    the first row as it is) where ``up``, else unfiltered."""
    h = image.shape[0]
    if image.dtype == np.uint16:
        image = image.astype(">u2")
    raw = np.ascontiguousarray(image).view(np.uint8).reshape(h, -1)
    rows = np.empty((h, raw.shape[1] + 1), np.uint8)
    rows[:, 0] = _FILTER_UP if up else _FILTER_NONE
    if up:
        rows[0, 1:] = raw[0]
        np.subtract(raw[1:], raw[:-1], out=rows[1:, 1:])
    else:
        rows[:, 1:] = raw
    return rows


#: bytes at a PNG file's start that hold its size: the signature, IHDR's length and type,
#: then its width and height (big-endian)
HEADER_BYTES = 24


def header_size(head: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG file's first :data:`HEADER_BYTES` bytes, without decoding
    it; None where they are not a PNG's (too short, another signature, no IHDR first)."""
    if len(head) < HEADER_BYTES or head[:8] != SIGNATURE or head[12:16] != b"IHDR":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def is_png(path: str | Path) -> bool:
    """Whether the file at ``path`` starts with PNG's signature."""
    with open(path, "rb") as fh:
        return fh.read(len(SIGNATURE)) == SIGNATURE


#: the bytes from which :func:`header_format` reads the bit depth and colour type
FORMAT_BYTES = 26

#: PNG's colour types (the IHDR byte after the bit depth)
GREY, RGB, PALETTE, GREY_ALPHA, RGB_ALPHA = 0, 2, 3, 4, 6


def header_format(head: bytes) -> tuple[int, int] | None:
    """(bit depth, colour type) from a PNG file's first :data:`FORMAT_BYTES` bytes, without
    decoding it; None where they are not a PNG's header."""
    if len(head) < FORMAT_BYTES or header_size(head) is None:
        return None
    return head[24], head[25]


def encode_png(image: np.ndarray, level: int = 1) -> bytes:
    """The PNG bytes of ``image`` (grey (H, W) or (H, W, 1), or RGB (H, W, 3); uint8 or
    uint16) at ``level`` (module docstring: 0 stored, 1-3 libdeflate's levels). The deflated
    data is copied once, into the returned bytes."""
    import deflate  # noqa: PLC0415  (only where a PNG is written)

    if image.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"PNG samples are uint8 or uint16, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    channels = 1 if image.ndim == 2 else image.shape[2]
    if image.ndim not in (2, 3) or channels not in _COLOUR_TYPE:
        raise ValueError(f"PNG images here are grey (H, W) or (H, W, 1), or RGB (H, W, 3), "
                         f"got shape {image.shape}")
    if level not in LEVELS:
        raise ValueError(f"PNG level {level}: use one of {LEVELS} (0 = stored)")
    level = int(level)
    h, w = image.shape[:2]
    if h == 0 or w == 0:
        raise ValueError(f"a PNG needs at least one pixel, got shape {image.shape}")
    rows = filtered_rows(image, up=level > 0)
    data = memoryview(zlib.compress(rows, 0) if level == 0
                      else deflate.zlib_compress(rows, level))
    header = struct.pack(">IIBBBBB", w, h, 8 * image.dtype.itemsize, _COLOUR_TYPE[channels],
                         0, 0, 0)
    parts = [SIGNATURE, *chunk(b"IHDR", header)]
    for a in range(0, max(len(data), 1), IDAT_BYTES):
        parts += chunk(b"IDAT", data[a:a + IDAT_BYTES])
    return b"".join(parts + chunk(b"IEND", b""))


#: a whole PNG's last 12 bytes: the empty IEND chunk and its CRC
_END = b"".join(chunk(b"IEND", b""))


#: what :func:`damage` says of a file of no bytes
EMPTY = "empty"


def damage(path: str | Path) -> str | None:
    """What makes the image file at ``path`` unreadable before any decoder sees it:
    :data:`EMPTY`, where a PNG is cut short (:func:`truncation`), or None."""
    return EMPTY if Path(path).stat().st_size == 0 else truncation(path)


def truncation(path: str | Path) -> str | None:
    """Where a PNG file is cut short, or None when its chunks run to IEND (or it is no PNG).

    A copy or download that stopped early leaves a PNG without its end; libpng then
    prints its own "Read Error" before the reader can say which file and why. The file's
    last 12 bytes are IEND on every whole PNG that nothing was appended to, so the common
    case reads 12 bytes; otherwise the chunk headers are walked (a seek per chunk)."""
    path = Path(path)
    size = path.stat().st_size
    with open(path, "rb") as fh:
        if fh.read(len(SIGNATURE)) != SIGNATURE:
            return None
        if size >= 20:
            fh.seek(size - 12)
            if fh.read(12) == _END:
                return None
        pos = len(SIGNATURE)
        while True:
            fh.seek(pos)
            head = fh.read(8)
            if len(head) < 8:
                return f"cut short after {pos} bytes (no IEND chunk)"
            length, kind = int.from_bytes(head[:4], "big"), head[4:]
            end = pos + 12 + length
            if end > size:
                return (f"cut short in its {kind.decode('latin-1')!r} chunk at byte {pos} "
                        f"({size - pos} of its {12 + length} bytes present)")
            if kind == b"IEND":
                return None
            pos = end
