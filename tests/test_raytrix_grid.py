"""Raytrix calibration reader/writer and the microlens grid, against every fixture."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from plenocal.grid import MicrolensGrid
from plenocal.io.raytrix import CalibError, calib_to_xml, parse_calib, read_calib

# shared/ lies beside the repository (in CI too)
FIXTURES = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "raytrix-calib"
# sensor sizes of the published sequences (README of the fixtures; others 4K UHD)
SIZES = {"ChessPieces": (3840, 2160), "Fujita2": (2048, 2048), "NagoyaFrog": (2048, 2048),
         "TempleBoatGiantR32": (6464, 4852)}
FILES = sorted(FIXTURES.glob("*.xml"))


def test_fixtures_present():
    assert len(FILES) == 7, f"expected the 7 Raytrix fixtures in {FIXTURES}"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_fixture_grid_puts_lenses_where_the_file_says(path: Path):
    calib = read_calib(path)
    W, H = SIZES.get(path.stem, (3840, 2160))
    grid = MicrolensGrid(calib, W, H)
    # the lens at the grid origin is at image centre + offset (file y axis points up)
    expected = np.array([(W - 1) / 2 + calib.offset[0], (H - 1) / 2 - calib.offset[1]])
    d = np.linalg.norm(grid.centres - expected, axis=1)
    assert d.min() < 1e-9
    # every neighbour at exactly one diameter, in the six lattice directions
    nb = grid.neighbours
    have = nb >= 0
    dist = np.linalg.norm(grid.centres[nb[have]] - np.repeat(grid.centres, 6, axis=0)[
        have.ravel()], axis=1)
    np.testing.assert_allclose(dist, calib.diameter, rtol=1e-9)
    # lattice direction: the rotation in the file, modulo the 60 degrees of a hex grid
    v = grid.neighbour_vectors[0]
    angle_up = math.atan2(-v[1], v[0])  # back to the file's y-up frame
    diff = (angle_up - calib.rotation) % (math.pi / 3)
    assert min(diff, math.pi / 3 - diff) < 1e-6
    # lenses cover the sensor densely: count ~ area / (D^2 sqrt(3)/2)
    expected_n = W * H / (calib.diameter ** 2 * math.sqrt(3) / 2)
    assert abs(len(grid) - expected_n) / expected_n < 0.05
    # lens types: every lens has one; with three types each takes a third and a lens
    # never shares its type with a direct neighbour
    if len(calib.lens_types) == 3:
        counts = np.bincount(grid.types, minlength=3)
        assert (np.abs(counts / len(grid) - 1 / 3) < 0.02).all()
        same = grid.types[nb[have]] == np.repeat(grid.types, 6)[have.ravel()]
        assert not same.any()


def test_type_offsets_follow_the_file():
    """ChessPieces: type 1 is the right neighbour (+lens_base_x) of a type-0 lens."""
    calib = read_calib(FIXTURES / "ChessPieces.xml")
    grid = MicrolensGrid(calib, 3840, 2160)
    origin = int(np.argmin(np.linalg.norm(grid.centres - grid.origin, axis=1)))
    assert grid.types[origin] == 0
    right = grid.neighbours[origin, 0]  # HEX_STEPS[0] = (1, 0): +x in the image
    assert grid.centres[right, 0] > grid.centres[origin, 0]
    assert grid.types[right] == 1


def test_temple_boat_rotation_applied():
    """A slightly rotated MLA: the lens 40 pitches right of the origin moves up by
    40 D sin(rotation) (counter-clockwise in the file's y-up frame)."""
    calib = read_calib(FIXTURES / "TempleBoatGiantR32.xml")
    grid = MicrolensGrid(calib, 6464, 4852)
    target = grid.origin + 40 * calib.diameter * np.array(
        [math.cos(calib.rotation), -math.sin(calib.rotation)])
    d = np.linalg.norm(grid.centres - target, axis=1)
    assert d.min() < 1e-6
    assert 40 * calib.diameter * math.sin(calib.rotation) > 1.0  # the test is not vacuous


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_round_trip(path: Path):
    calib = read_calib(path)
    again = parse_calib(calib_to_xml(calib), source="roundtrip")
    assert again == calib


GOOD = (FIXTURES / "Fujita2.xml").read_text() if FIXTURES.is_dir() else ""


@pytest.mark.parametrize("mutate, key", [
    (lambda s: s.replace("<diameter units=\"pix\">23.202295303345</diameter>", ""), "diameter"),
    (lambda s: s.replace("23.202295303345", "twenty"), "diameter"),
    (lambda s: s.replace("<rotation units=\"rad\">1.570796370506</rotation>",
                         "<rotation units=\"rad\">nan</rotation>"), "rotation"),
    (lambda s: s.replace("<max>3.200000047684</max>", ""), "depth_range"),
    # written in degrees (90) under units="rad", and a diameter in millimetres
    (lambda s: s.replace("<rotation units=\"rad\">1.570796370506</rotation>",
                         "<rotation units=\"rad\">90.0</rotation>"), "rotation: 90.0 rad is "
     "more than a full turn: degrees?"),
    (lambda s: s.replace("<diameter units=\"pix\">23.202295303345</diameter>",
                         "<diameter units=\"mm\">0.1276</diameter>"), "diameter: units='mm', "
     "where RayCalibData gives 'pix'"),
    (lambda s: s.replace("</RayCalibData>", ""), "malformed"),
    (lambda s: s.replace("RayCalibData", "Other"), "RayCalibData"),
    (lambda s: s.replace("<lens_base_y units=\"lens\">\n    <x>0.866025388241</x>",
                         "<lens_base_y units=\"lens\">\n    <x>0.2</x>"), "lens_base"),
])
def test_malformed_files_name_file_and_key(tmp_path: Path, mutate, key):
    p = tmp_path / "bad.xml"
    p.write_text(mutate(GOOD))
    with pytest.raises(CalibError) as exc:
        read_calib(p)
    assert str(p) in str(exc.value)
    assert key in str(exc.value)


def test_tspc_corner_file_points_at_the_calibration(tmp_path: Path):
    """The MPEG TSPC sequences ship two XML files; the corner measurements given as
    CALIB.xml are refused with the file to pass instead."""
    p = tmp_path / "Boys2_TSPC_corners_calib.xml"
    p.write_text('<TSPCCalibData><diameter unit="pix">70</diameter></TSPCCalibData>')
    with pytest.raises(CalibError, match=r"Boys2_TSPC_corners_calib\.xml: <root>: expected "
                                         r"<RayCalibData>, found <TSPCCalibData>: this is the "
                                         r"TSPC tools' corner measurements.*RayCalibData file"):
        read_calib(p)


@pytest.mark.parametrize("text", ["inf", "yes", "2", "1e400", "nan"])
def test_bad_is_real_names_file_and_key(tmp_path: Path, text: str):
    """Issue 34: <isReal>inf</isReal> gave a bare OverflowError, <isReal>yes</isReal> a
    bare ValueError, outside the CalibError that the converter turns into a named error."""
    good = (FIXTURES / "Boys2.xml").read_text()
    assert "<isReal>1</isReal>" in good
    p = tmp_path / "calib.xml"
    p.write_text(good.replace("<isReal>1</isReal>", f"<isReal>{text}</isReal>"))
    with pytest.raises(CalibError, match="isReal") as exc:
        read_calib(p)
    assert str(p) in str(exc.value)
    assert read_calib(FIXTURES / "Boys2.xml").is_real == 1


def test_entity_expansion_refused(tmp_path: Path):
    bomb = ('<?xml version="1.0"?>\n<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa">'
            '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>\n'
            '<RayCalibData><diameter>&b;</diameter></RayCalibData>')
    p = tmp_path / "bomb.xml"
    p.write_text(bomb)
    with pytest.raises(CalibError, match="unsafe XML"):
        read_calib(p)


def test_external_entity_refused(tmp_path: Path):
    xxe = ('<?xml version="1.0"?>\n<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>\n'
           '<RayCalibData><diameter>&x;</diameter></RayCalibData>')
    p = tmp_path / "xxe.xml"
    p.write_text(xxe)
    with pytest.raises(CalibError, match="unsafe XML"):
        read_calib(p)


def test_missing_file_is_a_clear_error(tmp_path: Path):
    with pytest.raises(CalibError, match="cannot read"):
        read_calib(tmp_path / "nope.xml")


@pytest.mark.parametrize("encoding", ["Shift_JIS", "GBK", "EUC-JP", "ISO-8859-1"])
def test_a_declared_encoding_that_python_reads_is_read(tmp_path: Path, encoding: str):
    """A declaration of a multi-byte encoding (a file saved on a Japanese or Chinese
    system) gave XML's parser's bare ValueError "multi-byte encodings are not supported",
    outside the CalibError that the converter and the workflow name: it is read by
    Python's codec, a comment in that encoding included, to the same values."""
    body = GOOD.split("?>", 1)[1] if GOOD.lstrip().startswith("<?xml") else GOOD
    p = tmp_path / "calib.xml"
    comment = "<!-- 名古屋 -->\n" if encoding != "ISO-8859-1" else "<!-- Zürich -->\n"
    p.write_bytes(f'<?xml version="1.0" encoding="{encoding}"?>\r\n{comment}{body}'
                  .encode(encoding))
    assert read_calib(p) == parse_calib(GOOD)


@pytest.mark.parametrize("encoding", ["utf8x", "unicode"])
def test_a_declared_encoding_nobody_knows_names_file_and_remedy(tmp_path: Path,
                                                                encoding: str):
    """An encoding that neither XML's parser nor Python knows gave a bare LookupError."""
    body = GOOD.split("?>", 1)[1] if GOOD.lstrip().startswith("<?xml") else GOOD
    p = tmp_path / "calib.xml"
    p.write_text(f'<?xml version="1.0" encoding="{encoding}"?>\n{body}')
    with pytest.raises(CalibError, match=rf"calib\.xml: <document>: .*'{encoding}'.*save the "
                                         r"file as UTF-8"):
        read_calib(p)


@pytest.mark.parametrize("element, extra", [
    ("<diameter", '<diameter units="pix">30.0</diameter>'),
    ("<rotation", '<rotation units="rad">0.5</rotation>'),
    ("<offset", '<offset units="pix"><x>0.0</x><y>0.0</y></offset>'),
    ("<lens_border", '<lens_border units="pix">2.0</lens_border>'),
])
def test_an_element_given_twice_is_refused(tmp_path: Path, element: str, extra: str):
    """A second copy of an element was ignored without a word (the first one read): a
    file with two diameters or two offsets converted on whichever came first."""
    i = GOOD.index(element)
    p = tmp_path / "calib.xml"
    p.write_text(GOOD[:i] + extra + GOOD[i:])
    key = element.lstrip("<")
    with pytest.raises(CalibError, match=rf"calib\.xml: {key}: given 2 times .*keep the one"):
        read_calib(p)
