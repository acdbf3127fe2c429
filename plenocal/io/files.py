"""File I/O with the workflow's guarantees: atomic writes and byte-stable encodings.

Every writer goes through a temporary file in the target folder followed by
``os.replace``, so a job killed mid-write never leaves a half-written output that a
rerun could trust. JSON is written with sorted keys and fixed float formatting so
that the same numbers give the same bytes.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import tempfile
import zipfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _atomic(path: str | Path, write: Callable[[Any], None], mode: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, mode) as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        # mkstemp creates 0600 files: give the output the usual permissions
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


TEMP_DIR_SUFFIX = ".tmpdir"


def clean_stale_temps(parent: str | Path, prefix: str) -> list[Path]:
    """Remove the temporary folders ``<prefix>*.tmpdir`` in ``parent`` that a killed job
    left behind (Snakemake runs one job per output at a time, so none is in use).
    Returns what was removed."""
    import shutil  # noqa: PLC0415

    parent = Path(parent)
    if not parent.is_dir():
        return []
    stale = sorted(p for p in parent.iterdir() if p.is_dir() and p.name.startswith(prefix)
                   and p.name.endswith(TEMP_DIR_SUFFIX))
    for p in stale:
        shutil.rmtree(p, ignore_errors=True)
    return stale


def make_temp_dir(parent: str | Path, prefix: str) -> Path:
    """A new temporary folder ``<prefix><random>.tmpdir`` in ``parent``, after removing the
    stale ones of the same prefix (a killed job's), readable as the umask allows."""
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temps(parent, prefix)
    tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=TEMP_DIR_SUFFIX, dir=parent))
    # mkdtemp creates drwx------: other users of a shared cluster could not read it
    os.chmod(tmp, 0o777 & ~_umask())
    return tmp


def atomic_write_dir(folder: str | Path, write: Callable[[Path], None]) -> None:
    """Fill a folder atomically: ``write`` fills a temporary sibling, which then
    replaces ``folder`` (a killed job leaves no half-written folder under its name, and
    its temporary sibling is removed by the next write). The folder gets the usual
    permissions (0o777 less the umask), not mkdtemp's 0o700."""
    import shutil  # noqa: PLC0415

    folder = Path(folder)
    tmp = make_temp_dir(folder.parent, f".{folder.name}.")
    try:
        write(tmp)
        if folder.exists():
            shutil.rmtree(folder)
        os.replace(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


#: the prefix of :func:`staged_outputs`' temporary folder inside the output folder
STAGE_PREFIX = ".staged."


@contextmanager
def staged_outputs(folder: str | Path, last: Sequence[str] = ()) -> Iterator[Path]:
    """A run's outputs made in a temporary folder inside ``folder`` (the block writes to
    the path it is given) and moved into ``folder`` when the block ends without an error,
    each file or folder replacing its namesake there, those named in ``last`` after the
    others (the run's record, which says the rest is there). On an error the temporary
    folder is removed and ``folder`` keeps what it held: a rerun that fails neither leaves
    half its outputs nor mixes them with the previous run's. A killed run's temporary
    folder is removed by the next one (:func:`make_temp_dir`). The moves are renames in
    one file system, no copies; until they are made the previous outputs and the new ones
    take space side by side."""
    import shutil  # noqa: PLC0415

    folder = Path(folder)
    stage = make_temp_dir(folder, STAGE_PREFIX)
    try:
        yield stage
        names = sorted(p.name for p in stage.iterdir())
        for name in [n for n in names if n not in last] + [n for n in last if n in names]:
            src, dst = stage / name, folder / name
            if dst.is_dir() and not dst.is_symlink():
                shutil.rmtree(dst)
            elif src.is_dir() and (dst.exists() or dst.is_symlink()):
                dst.unlink()
            os.replace(src, dst)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    _atomic(path, lambda fh: fh.write(data), "wb")


def atomic_write_text(path: str | Path, text: str) -> None:
    _atomic(path, lambda fh: fh.write(text), "w")


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return _jsonable(float(obj))
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, float):
        if obj != obj or obj in (float("inf"), float("-inf")):
            return None
        # 12 significant digits: stable bytes, far below any tolerance of the project
        return float(f"{obj:.12g}")
    return obj


def dumps_json(obj: Any) -> str:
    return json.dumps(_jsonable(obj), indent=2, sort_keys=True) + "\n"


def write_json(path: str | Path, obj: Any) -> None:
    atomic_write_text(path, dumps_json(obj))


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes, hex (read in chunks: a tarball or a view alike)."""
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def read_json(path: str | Path) -> Any:
    """The JSON document in ``path``; ValueError naming the file and the remedy where it is
    empty or not JSON (a file cut short or edited: Snakemake does not notice, as its time
    is newer than its inputs')."""
    with open(path) as fh:
        try:
            return json.load(fh)
        except json.JSONDecodeError as exc:
            what = "an empty file" if not exc.doc.strip() else (
                f"not valid JSON ({exc.msg}, line {exc.lineno} column {exc.colno})")
            raise ValueError(f"{path}: {what}; if the workflow wrote it, delete it and run "
                             "again to make it anew") from None


def write_npy(path: str | Path, array: np.ndarray) -> None:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(array), allow_pickle=False)
    atomic_write_bytes(path, buf.getvalue())


#: what numpy raises on a .npy or .npz cut short or overwritten (a truncated .npy: a
#: ValueError; a truncated .npz: zipfile.BadZipFile; a bad header: ValueError / EOFError);
#: an OSError (no permission, a folder) is not damage and passes as it is
_NPY_DAMAGE = (ValueError, EOFError, KeyError, zipfile.BadZipFile)


def _npy_error(path: str | Path, exc: Exception) -> ValueError:
    return ValueError(f"{path}: not a readable numpy file ({type(exc).__name__}: {exc}); "
                      "if the workflow wrote it, delete it and run again to make it anew")


def read_npy(path: str | Path) -> np.ndarray:
    """The array in the ``.npy`` file ``path`` (no pickles); FileNotFoundError where it
    is missing, ValueError naming the file and the remedy where it is damaged (cut short
    or overwritten in place: Snakemake does not notice, as its time is newer than its
    inputs')."""
    try:
        return np.load(path, allow_pickle=False)
    except _NPY_DAMAGE as exc:
        raise _npy_error(path, exc) from None


def read_npz(path: str | Path) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` file ``path``, read in full (no pickles); errors as
    :func:`read_npy`'s."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except _NPY_DAMAGE as exc:
        raise _npy_error(path, exc) from None


#: compression level of every PNG the workflow writes (:func:`write_image`): libdeflate's
#: level 1 with PNG's "up" filter (:mod:`plenocal.io.png` gives its measurements; issue 35).
PNG_LEVEL = 1


#: level of the simulator's lenslet images (:func:`write_image` ``level``): stored, not
#: compressed - the noisy 12-bit pixels compress to 70 % at best, and a 2048 x 1536 image
#: then encodes in 0.05 s instead of 0.22 s and decodes in 0.05 s instead of 0.15 s, for
#: 18.9 MB instead of 13.3 MB on disk (issue 15).
LENSLET_PNG_LEVEL = 0


def write_image(path: str | Path, image: np.ndarray, level: int = PNG_LEVEL) -> None:
    """Write a PNG (uint8 or uint16, grey or RGB) deterministically and atomically
    (``level``: 0 stored, 1-3 libdeflate's levels; :mod:`plenocal.io.png`).

    The encoder is our own container around libdeflate (the ``deflate`` package): no time
    stamps or other ancillary chunks, and a deflate stream made in one call from the
    whole image, so the same pixels give the same bytes. Stored data (level 0) is written
    unfiltered; compressed data with PNG's "up" filter on every row (issue 15 measured it
    against libpng's per-row choice: 2x faster to encode and decode for a few % more
    bytes). The speed against OpenCV's encoder and ISA-L: :mod:`plenocal.io.png`.
    libdeflate lets go of the GIL (:func:`write_images` on threads).
    """
    from plenocal.io.png import encode_png  # noqa: PLC0415

    try:
        data = encode_png(np.asarray(image), level)
    except (TypeError, ValueError) as err:
        raise type(err)(f"{path}: {err}") from None
    atomic_write_bytes(path, data)


def write_images(items: Iterable[tuple[str | Path, np.ndarray]], threads: int = 1,
                 level: int = PNG_LEVEL) -> None:
    """:func:`write_image` for every (path, image), on ``threads`` threads (libdeflate
    and the file writes let go of the GIL; each file is written atomically on its own)."""
    items = list(items)
    if threads <= 1 or len(items) <= 1:
        for path, image in items:
            write_image(path, image, level)
        return
    from concurrent.futures import ThreadPoolExecutor  # noqa: PLC0415

    with ThreadPoolExecutor(max_workers=threads) as pool:
        for _ in pool.map(lambda item: write_image(item[0], item[1], level), items):
            pass  # re-raises a worker's error


class TruncatedImageError(OSError):
    """A PNG whose file ends before its IEND chunk (a copy or write that stopped early)."""


def read_image(path: str | Path) -> np.ndarray:
    """Read a PNG as stored (uint8 or uint16; RGB order for colour)."""
    import cv2  # noqa: PLC0415

    from plenocal.io.png import EMPTY, damage  # noqa: PLC0415

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: image not found")
    cut = damage(path)  # before libpng, which prints its own "Read Error" first
    if cut == EMPTY:
        raise OSError(f"{path}: an empty file")
    if cut is not None:
        raise TruncatedImageError(f"{path}: a truncated PNG, {cut}: the file was not "
                                  "copied or written whole; copy or make it again")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise OSError(f"{path}: not a readable image: OpenCV decodes PNG, TIFF and JPEG, and "
                      "a damaged file fails so too")
    if img.ndim == 3 and img.shape[2] == 4:
        return np.ascontiguousarray(img[:, :, 2::-1])
    if img.ndim == 3:  # BGR -> RGB in place: no second copy of a 40-MP frame
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB, dst=img)
    return np.ascontiguousarray(img)


def to_float(image: np.ndarray) -> np.ndarray:
    """uint8/uint16 image to float32 in [0, 1]."""
    if image.dtype == np.uint8:
        return image.astype(np.float32) / 255.0
    if image.dtype == np.uint16:
        return image.astype(np.float32) / 65535.0
    return image.astype(np.float32)


def to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(image) * 255.0), 0, 255).astype(np.uint8)
