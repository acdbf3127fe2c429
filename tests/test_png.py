"""plenocal.io.png: the PNG files write_image makes, read back by OpenCV and Pillow."""

import struct
import zlib

import cv2  # noqa: F401  (before pycolmap anywhere in the session: DESIGN.md)
import numpy as np
import pytest
from PIL import Image

from plenocal.io.files import read_image, write_image
from plenocal.io.png import SIGNATURE, VIEW_BITS, encode_png, view_dtype


def _chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    assert data[:8] == SIGNATURE
    out, pos = [], 8
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        crc = int.from_bytes(data[pos + 8 + n:pos + 12 + n], "big")
        assert crc == zlib.crc32(body, zlib.crc32(kind))
        out.append((kind, body))
        pos += 12 + n
    return out


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("shape", [(1, 1), (5, 7), (5, 7, 1), (6, 3, 3), (37, 53, 3)])
@pytest.mark.parametrize("level", [0, 1, 3])
def test_png_round_trip(tmp_path, dtype, shape, level):
    """Every level, depth and layout gives the pixels back through OpenCV (read_image) and,
    but for 16-bit RGB (which Pillow reduces to 8 bits), Pillow; the same pixels give the
    same bytes."""
    top = np.iinfo(dtype).max
    img = np.random.default_rng(len(shape) + level).integers(0, top, shape, endpoint=True,
                                                             dtype=dtype)
    img[0, 0] = top  # both ends present
    img.reshape(-1)[-1] = 0
    path = tmp_path / "a.png"
    write_image(path, img, level=level)
    back = read_image(path)
    assert back.dtype == dtype
    assert np.array_equal(back.reshape(img.shape), img)
    if not (dtype == np.uint16 and img.ndim == 3 and img.shape[2] == 3):
        with Image.open(path) as pil:
            assert np.array_equal(np.asarray(pil).reshape(img.shape), img)
    write_image(tmp_path / "b.png", img.copy(), level=level)
    assert (tmp_path / "b.png").read_bytes() == path.read_bytes()


def test_png_layout_and_filters():
    """IHDR as written (size, depth, colour type), one IDAT, IEND; stored rows unfiltered,
    compressed rows with the "up" filter holding the differences to the row above."""
    img = (np.arange(4 * 5 * 3, dtype=np.uint16).reshape(4, 5, 3) * 1000)
    for level, filt in ((0, 0), (1, 2)):
        chunks = _chunks(encode_png(img, level))
        assert [k for k, _ in chunks] == [b"IHDR", b"IDAT", b"IEND"]
        assert struct.unpack(">IIBBBBB", chunks[0][1]) == (5, 4, 16, 2, 0, 0, 0)
        rows = np.frombuffer(zlib.decompress(chunks[1][1]), np.uint8).reshape(4, 1 + 5 * 3 * 2)
        assert (rows[:, 0] == filt).all()
        raw = img.astype(">u2").view(np.uint8).reshape(4, -1)
        expect = raw if filt == 0 else np.vstack([raw[:1], raw[1:] - raw[:-1]])
        assert np.array_equal(rows[:, 1:], expect)
    grey = _chunks(encode_png(np.zeros((2, 3), np.uint8)))[0][1]
    assert struct.unpack(">IIBBBBB", grey) == (3, 2, 8, 0, 0, 0, 0)


def test_png_refuses_what_it_cannot_write(tmp_path):
    """Other sample types, channel counts, levels and empty images are refused, naming the
    file; nothing is left behind."""
    cases = [(np.zeros((2, 2), np.float32), TypeError, "uint8 or uint16"),
             (np.zeros((2, 2, 4), np.uint8), ValueError, "grey"),
             (np.zeros((0, 2), np.uint8), ValueError, "at least one pixel")]
    for img, err, text in cases:
        with pytest.raises(err, match=text) as info:
            write_image(tmp_path / "bad.png", img)
        assert "bad.png" in str(info.value)
    with pytest.raises(ValueError, match="level 9"):
        write_image(tmp_path / "bad.png", np.zeros((2, 2), np.uint8), level=9)
    assert not list(tmp_path.iterdir())


def test_png_splits_large_data_over_idat_chunks(tmp_path, monkeypatch):
    """Deflated data longer than a chunk may hold goes into consecutive IDAT chunks (here
    cut every 7 bytes), which readers join into the one zlib stream."""
    import plenocal.io.png as png

    monkeypatch.setattr(png, "IDAT_BYTES", 7)
    img = np.random.default_rng(5).integers(0, 65535, (20, 30, 3), dtype=np.uint16)
    data = png.encode_png(img, 1)
    kinds = [k for k, _ in _chunks(data)]
    assert kinds[0] == b"IHDR" and kinds[-1] == b"IEND"
    assert set(kinds[1:-1]) == {b"IDAT"} and len(kinds) > 10
    (tmp_path / "split.png").write_bytes(data)
    assert np.array_equal(read_image(tmp_path / "split.png"), img)


def test_view_bits_choose_the_samples_and_pillow_reads_16_bit_colour_as_8_bit(tmp_path):
    """``plenocal convert --png-bits``: 8 by default, 16 on request, nothing else; and why 8
    stays the default: Pillow opens a 16-bit colour PNG as 8-bit RGB (its high bytes)."""
    assert VIEW_BITS == 8 and view_dtype(None) is np.uint8
    assert view_dtype(8) is np.uint8 and view_dtype(16) is np.uint16
    with pytest.raises(ValueError, match="8 or 16 bits per sample, not 12"):
        view_dtype(12)
    rgb = ((np.arange(4 * 6 * 3).reshape(4, 6, 3) * 911) % 65536).astype(np.uint16)
    path = tmp_path / "v.png"
    write_image(path, rgb)
    assert np.array_equal(read_image(path), rgb)
    with Image.open(path) as im:
        assert im.mode == "RGB"
        assert np.array_equal(np.asarray(im), (rgb >> 8).astype(np.uint8))
