"""Raytrix ``RayCalibData`` calibration files: read and write.

The schema (as written by Raytrix software; see ``shared/fixtures/raytrix-calib``)::

    <RayCalibData version="1.0">
      <offset units="pix"><x/><y/></offset>      grid origin - image centre, y up
      <diameter units="pix"/>                    micro-image pitch D
      <rotation units="rad"/>                    grid rotation, counter-clockwise (y up)
      <lens_border units="pix"/>                 unusable rim: D' = D - 2 lens_border
      <tcp units="virtual_depth"/>               optional
      <lens_base_x units="lens"><x/><y/></lens_base_x>
      <lens_base_y units="lens"><x/><y/></lens_base_y>
      <sub_grid_base units="lens"><x/><y/></sub_grid_base>   lens-type cell (optional)
      <distortion type="..."> ... </distortion>  optional, kept as read
      <lens_type id="i"> <offset units="lens"><x/><y/></offset>
                         <depth_range units="virtual_depth"><min/><max/></depth_range>
      </lens_type> ...
      <k_matrix count="9"> ... </k_matrix>       optional, kept as text
    </RayCalibData>

Conventions (shared with PlenopticToolbox 2.0 and the MPEG reference software): the
image centre is ((W-1)/2, (H-1)/2) with pixel centres at integers; the file's ``y``
axis points up, so the grid origin in image coordinates is
``(cx + offset.x, cy - offset.y)``. Parsing uses :mod:`defusedxml`, which refuses
entity declarations, external entities and DTD tricks. A file is read in the encoding its
XML declaration names (multi-byte ones such as Shift_JIS by Python's codec, which XML's
parser lacks); an element the reader uses that is given twice is refused, not read from
its first copy.
"""

from __future__ import annotations

import codecs
import copy
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, tostring

import defusedxml.ElementTree as SafeET
from defusedxml import DefusedXmlException

from plenocal.io.files import atomic_write_text


class CalibError(ValueError):
    """A calibration file that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class LensType:
    id: int
    offset: tuple[float, float]  # lens units, file frame (y up)
    depth_min: float  # virtual depth
    depth_max: float


@dataclass(frozen=True)
class RayCalib:
    diameter: float
    offset: tuple[float, float]
    rotation: float
    lens_border: float
    lens_base_x: tuple[float, float]
    lens_base_y: tuple[float, float]
    lens_types: tuple[LensType, ...]
    sub_grid_base: tuple[float, float] | None = None
    tcp: float | None = None
    is_real: int | None = None
    distortion_xml: str | None = None  # kept verbatim for round trips
    k_matrix_xml: str | None = None
    source: str = field(default="<memory>", compare=False)

    @property
    def safe_diameter(self) -> float:
        """D' = D - 2 lens_border (the paper's D' = D - 2 px for lens_border = 1)."""
        return self.diameter - 2.0 * self.lens_border


def _err(source: str, key: str, why: str) -> CalibError:
    return CalibError(f"{source}: {key}: {why}")


def _single(root: Element, path: str, source: str) -> Element | None:
    """The one element at ``path`` (None where absent); CalibError where the file gives it
    more than once: which copy the camera's software meant cannot be told."""
    found = root.findall(path)
    if len(found) > 1:
        texts = ", ".join(repr(" ".join(t.strip() for t in e.itertext() if t.strip()))
                          for e in found)
        raise _err(source, path.replace("/", "."), f"given {len(found)} times ({texts}): "
                   "keep the one that is this camera's and delete the others")
    return found[0] if found else None


def _number(root: Element, path: str, source: str, required: bool = True) -> float | None:
    el = _single(root, path, source)
    if el is None:
        if required:
            raise _err(source, path.replace("/", "."), "missing")
        return None
    text = (el.text or "").strip()
    try:
        value = float(text)
    except ValueError:
        raise _err(source, path.replace("/", "."), f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise _err(source, path.replace("/", "."), f"not finite: {text!r}")
    return value


def _flag(root: Element, path: str, source: str) -> int | None:
    """An optional 0 / 1 flag (``isReal``); None where absent or empty."""
    el = _single(root, path, source)
    if el is None or not (el.text or "").strip():
        return None
    value = _number(root, path, source)
    if value not in (0.0, 1.0):
        raise _err(source, path, f"must be 0 or 1 (got {(el.text or '').strip()!r})")
    return int(value)


def _vec(root: Element, name: str, source: str, required: bool = True,
         keys: tuple[str, str] = ("x", "y")) -> tuple[float, float] | None:
    if _single(root, name, source) is None:
        if required:
            raise _err(source, name, "missing")
        return None
    a = _number(root, f"{name}/{keys[0]}", source)
    b = _number(root, f"{name}/{keys[1]}", source)
    assert a is not None and b is not None
    return (a, b)


#: the units RayCalibData writes for the values the converter reads, where a file names
#: them (a file that names none is read as these)
UNITS = {"diameter": "pix", "lens_border": "pix", "rotation": "rad", "offset": "pix"}


def _check_units(root: Element, source: str) -> None:
    """CalibError where a value of :data:`UNITS` names another unit than RayCalibData's
    (a diameter in mm, a rotation in deg): it would be read as pixels or radians."""
    for name, unit in UNITS.items():
        el = root.find(name)
        given = None if el is None else el.get("units")
        if given is not None and given.strip().lower() != unit:
            raise _err(source, name, f"units={given!r}, where RayCalibData gives {unit!r}: "
                       f"convert the value to {unit} and write units=\"{unit}\"")


#: the encoding an XML declaration names
_DECLARED_ENCODING = re.compile(
    rb"""^(?:\xef\xbb\xbf)?\s*<\?xml[^>]*?encoding\s*=\s*["']([^"']+)["']""")


def _decoded(data: bytes, source: str) -> str:
    """``data`` decoded by the encoding its XML declaration names, for the encodings that
    Python reads and XML's parser does not (multi-byte ones: Shift_JIS, GBK, EUC-JP);
    CalibError where the declaration names none that Python knows."""
    m = _DECLARED_ENCODING.match(data)
    name = m.group(1).decode("ascii", "replace") if m else "?"
    try:
        codecs.lookup(name)
        return data.decode(name)
    except (LookupError, UnicodeDecodeError) as exc:
        raise _err(source, "<document>", f"cannot be read as the encoding its XML "
                   f"declaration names ({name!r}: {exc}): save the file as UTF-8 and write "
                   'encoding="UTF-8" in its first line') from None


def parse_calib(text: str | bytes, source: str = "<string>") -> RayCalib:
    """Parse RayCalibData XML text. Raises :class:`CalibError` naming ``source``."""
    try:
        try:
            root = SafeET.fromstring(text, forbid_dtd=True)
        except DefusedXmlException:
            raise
        except (ValueError, LookupError):
            # XML's parser reads no multi-byte encoding a declaration names ("multi-byte
            # encodings are not supported") nor one it does not know: Python's codecs do
            if not isinstance(text, bytes):
                raise
            root = SafeET.fromstring(_decoded(text, source), forbid_dtd=True)
    except DefusedXmlException as exc:
        raise _err(source, "<document>", f"refused unsafe XML ({type(exc).__name__})") from None
    except SafeET.ParseError as exc:
        raise _err(source, "<document>", f"malformed XML: {exc}: a file cut short in a "
                   "copy, saved in another encoding than its first line declares, or not a "
                   "calibration file; take the camera's RayCalibData file as its software "
                   "wrote it") from None
    if root.tag != "RayCalibData":
        hint = (": this is the TSPC tools' corner measurements, not the camera's calibration; "
                "pass the sequence's RayCalibData file (e.g. Boys2.xml beside "
                "Boys2_TSPC_corners_calib.xml)" if root.tag == "TSPCCalibData" else "")
        raise _err(source, "<root>", f"expected <RayCalibData>, found <{root.tag}>{hint}")

    _check_units(root, source)
    diameter = _number(root, "diameter", source)
    assert diameter is not None
    if diameter <= 2.0:
        raise _err(source, "diameter", f"must be > 2 pixels (got {diameter})")
    lens_border = _number(root, "lens_border", source, required=False)
    lens_border = 1.0 if lens_border is None else lens_border
    if lens_border < 0 or 2 * lens_border >= diameter:
        raise _err(source, "lens_border", f"must be in [0, diameter/2) (got {lens_border})")
    rotation = _number(root, "rotation", source)
    assert rotation is not None
    if abs(rotation) > 2 * math.pi:
        raise _err(source, "rotation", f"{rotation} rad is more than a full turn: degrees? "
                   "RayCalibData gives the grid's rotation in radians (90 deg: 1.5708)")
    offset = _vec(root, "offset", source)
    bx = _vec(root, "lens_base_x", source)
    by = _vec(root, "lens_base_y", source)
    assert offset is not None and bx is not None and by is not None
    for name, v in (("lens_base_x", bx), ("lens_base_y", by)):
        n = math.hypot(*v)
        if not 0.9 < n < 1.1:
            raise _err(source, name, f"must be a unit vector in lens units (length {n:.4f})")
    cross = bx[0] * by[1] - bx[1] * by[0]
    if abs(abs(cross) - math.sqrt(3) / 2) > 0.05:
        raise _err(source, "lens_base_y",
                   "lens_base_x and lens_base_y do not span a hexagonal grid "
                   f"(|cross product| {abs(cross):.4f}, expected 0.866)")
    sub = _vec(root, "sub_grid_base", source, required=False)

    types: list[LensType] = []
    for i, el in enumerate(root.findall("lens_type")):
        ident = el.get("id")
        key = f"lens_type[{ident if ident is not None else i}]"
        try:
            tid = int(ident) if ident is not None else i
        except ValueError:
            raise _err(source, f"{key}.id", f"not an integer: {ident!r}") from None
        off = _vec(el, "offset", f"{source}: {key}")
        dmin = _number(el, "depth_range/min", f"{source}: {key}", required=False)
        dmax = _number(el, "depth_range/max", f"{source}: {key}", required=False)
        if dmin is None or dmax is None:
            raise _err(source, f"{key}.depth_range", "missing (the converter needs the "
                       "virtual-depth range of every lens type)")
        if not 0 < dmin < dmax:
            raise _err(source, f"{key}.depth_range", f"need 0 < min < max (got {dmin}, {dmax})")
        assert off is not None
        types.append(LensType(tid, off, dmin, dmax))
    if not types:
        raise _err(source, "lens_type", "missing (at least one lens type with a depth range)")
    ids = sorted(t.id for t in types)
    if ids != list(range(len(types))):
        raise _err(source, "lens_type.id", f"ids must be 0..{len(types) - 1} (got {ids})")
    if len(types) > 1 and sub is None:
        raise _err(source, "sub_grid_base", "missing although several lens types are given")
    is_real = _flag(root, "isReal", source)
    dist = _single(root, "distortion", source)
    kmat = _single(root, "k_matrix", source)
    return RayCalib(
        diameter=diameter, offset=offset, rotation=rotation, lens_border=lens_border,
        lens_base_x=bx, lens_base_y=by, lens_types=tuple(sorted(types, key=lambda t: t.id)),
        sub_grid_base=sub, tcp=_number(root, "tcp", source, required=False),
        is_real=is_real,
        distortion_xml=_canonical(dist) if dist is not None else None,
        k_matrix_xml=_canonical(kmat) if kmat is not None else None,
        source=source,
    )


def _canonical(el: Element) -> str:
    """An element as compact XML text (whitespace between tags dropped), for round trips."""
    el = copy.deepcopy(el)
    for node in el.iter():
        node.text = node.text.strip() if node.text and node.text.strip() else None
        node.tail = None
    return tostring(el, encoding="unicode")


def read_calib(path: str | Path) -> RayCalib:
    """Read a ``calib.xml``; a missing or unreadable file is a :class:`CalibError` too."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CalibError(f"{path}: cannot read calibration file: {exc.strerror}") from None
    return parse_calib(data, source=str(path))


def _fmt(x: float) -> str:
    return f"{x:.12f}"


def calib_to_xml(calib: RayCalib) -> str:
    """Serialise in Raytrix's layout (numbers with 12 decimals, as Raytrix writes them)."""
    root = Element("RayCalibData", version="1.0")

    def vec(parent: Element, name: str, v: tuple[float, float], units: str,
            keys: tuple[str, str] = ("x", "y")) -> Element:
        el = SubElement(parent, name, units=units)
        SubElement(el, keys[0]).text = _fmt(v[0])
        SubElement(el, keys[1]).text = _fmt(v[1])
        return el

    vec(root, "offset", calib.offset, "pix")
    if calib.is_real is not None:
        SubElement(root, "isReal").text = str(calib.is_real)
    SubElement(root, "diameter", units="pix").text = _fmt(calib.diameter)
    SubElement(root, "rotation", units="rad").text = _fmt(calib.rotation)
    SubElement(root, "lens_border", units="pix").text = _fmt(calib.lens_border)
    if calib.tcp is not None:
        SubElement(root, "tcp", units="virtual_depth").text = _fmt(calib.tcp)
    vec(root, "lens_base_x", calib.lens_base_x, "lens")
    vec(root, "lens_base_y", calib.lens_base_y, "lens")
    if calib.sub_grid_base is not None:
        vec(root, "sub_grid_base", calib.sub_grid_base, "lens")
    if calib.distortion_xml:
        root.append(SafeET.fromstring(calib.distortion_xml))
    for t in calib.lens_types:
        el = SubElement(root, "lens_type", id=str(t.id))
        vec(el, "offset", t.offset, "lens")
        vec(el, "depth_range", (t.depth_min, t.depth_max), "virtual_depth", ("min", "max"))
    if calib.k_matrix_xml:
        root.append(SafeET.fromstring(calib.k_matrix_xml))
    _indent(root)
    return '<?xml version="1.0"?>\n' + tostring(root, encoding="unicode") + "\n"


def _indent(el: Element, level: int = 0) -> None:
    pad = "\n" + "  " * level
    if len(el):
        if not (el.text or "").strip():
            el.text = pad + "  "
        for child in el:
            _indent(child, level + 1)
            if not (child.tail or "").strip():
                child.tail = pad + "  "
        if not (el[-1].tail or "").strip():
            el[-1].tail = pad
    elif level and not (el.tail or "").strip():
        el.tail = pad


def write_calib(calib: RayCalib, path: str | Path) -> None:
    atomic_write_text(path, calib_to_xml(calib))
