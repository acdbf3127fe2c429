"""plenocal.io.files: a run's outputs staged and moved into place (nothing half-written,
nothing of the previous run lost on a failure)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from plenocal.io.files import (
    STAGE_PREFIX,
    TruncatedImageError,
    read_image,
    read_json,
    read_npy,
    read_npz,
    staged_outputs,
    write_image,
    write_json,
)
from plenocal.io.png import truncation as png_truncation


def _tree(folder: Path) -> dict[str, bytes | None]:
    """Every path under ``folder`` -> its bytes (None for a folder)."""
    return {str(p.relative_to(folder)): (None if p.is_dir() else p.read_bytes())
            for p in sorted(folder.rglob("*"))}


def test_outputs_replace_their_namesakes_and_the_record_comes_last(tmp_path, monkeypatch):
    out = tmp_path / "out"
    (out / "frame_1").mkdir(parents=True)
    (out / "frame_1" / "old.png").write_bytes(b"old")
    (out / "a.png").write_bytes(b"old a")
    (out / "notes.txt").write_bytes(b"the user's")  # not an output: kept
    (out / "b").mkdir()  # a folder where the run writes a file: replaced
    moved: list[str] = []
    import plenocal.io.files as files_mod  # noqa: PLC0415

    replace = files_mod.os.replace
    monkeypatch.setattr(files_mod.os, "replace",
                        lambda src, dst: (moved.append(Path(dst).name), replace(src, dst)))
    with staged_outputs(out, last=("z_first.json", "record.json")) as stage:
        assert stage.parent == out and stage.name.startswith(STAGE_PREFIX)
        (stage / "record.json").write_bytes(b"{}")
        (stage / "a.png").write_bytes(b"new a")
        (stage / "b").write_bytes(b"new b")
        (stage / "frame_1").mkdir()
        (stage / "frame_1" / "new.png").write_bytes(b"new")
        (stage / "z_first.json").write_bytes(b"z")
    assert moved == ["a.png", "b", "frame_1", "z_first.json", "record.json"]
    assert _tree(out) == {"a.png": b"new a", "b": b"new b", "frame_1": None,
                          "frame_1/new.png": b"new", "notes.txt": b"the user's",
                          "record.json": b"{}", "z_first.json": b"z"}


def test_a_failure_leaves_the_folder_as_it_was(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.png").write_bytes(b"old a")
    (out / "record.json").write_bytes(b"old")
    before = _tree(out)
    with pytest.raises(RuntimeError, match="stopped"), staged_outputs(out, ("record.json",)
                                                                      ) as stage:
        (stage / "a.png").write_bytes(b"new a")
        (stage / "c.png").write_bytes(b"new c")
        raise RuntimeError("stopped")
    assert _tree(out) == before


def test_a_killed_runs_staging_folder_goes_with_the_next_run(tmp_path):
    out = tmp_path / "out"
    stale = out / f"{STAGE_PREFIX}abc.tmpdir"
    stale.mkdir(parents=True)
    (stale / "x.png").write_bytes(b"half")
    with staged_outputs(out) as stage:
        assert not stale.exists()
        (stage / "x.png").write_bytes(b"whole")
    assert _tree(out) == {"x.png": b"whole"}


def test_png_truncation_is_found_wherever_the_file_stops(tmp_path: Path):
    """Every prefix of a PNG short of its end is named as cut short; the whole file, one
    with bytes appended after IEND, and files that are no PNG are not (those are left to
    the decoder's own error)."""
    img = np.random.default_rng(0).integers(0, 65535, (40, 30, 3)).astype(np.uint16)
    whole_path = tmp_path / "whole.png"
    write_image(whole_path, img)
    whole = whole_path.read_bytes()
    assert png_truncation(whole_path) is None
    cut = tmp_path / "cut.png"
    for n in (8, 9, 33, 40, len(whole) // 2, len(whole) - 13, len(whole) - 1):
        cut.write_bytes(whole[:n])
        assert png_truncation(cut) is not None, n
        with pytest.raises(TruncatedImageError, match=r"cut.png: a truncated PNG, cut short"):
            read_image(cut)
    cut.write_bytes(whole + b"trailing")
    assert png_truncation(cut) is None and np.array_equal(read_image(cut), img)
    for other in (b"", b"GIF89a", b"not a png at all"):
        cut.write_bytes(other)
        assert png_truncation(cut) is None
        with pytest.raises(OSError, match="an empty file" if not other
                           else "not a readable image"):
            read_image(cut)


def test_an_empty_or_cut_json_file_is_named_with_its_remedy(tmp_path: Path):
    """An intermediate cut short or emptied by hand is newer than its inputs, so Snakemake
    does not make it again, and its reader stopped with json's bare "Expecting value":
    now the file and the remedy are named."""
    doc = tmp_path / "cameras.json"
    write_json(doc, {"cameras": {"a": [1, 2, 3]}})
    assert read_json(doc) == {"cameras": {"a": [1, 2, 3]}}
    text = doc.read_text()
    doc.write_text("")
    with pytest.raises(ValueError, match=rf"{doc}: an empty file; if the workflow wrote it, "
                                         "delete it and run again"):
        read_json(doc)
    doc.write_text(text[: len(text) // 2])
    with pytest.raises(ValueError, match=rf"{doc}: not valid JSON \(.*line \d+ column \d+\)"):
        read_json(doc)


def test_a_numpy_file_cut_or_overwritten_is_named_with_its_remedy(tmp_path: Path):
    """A depth map, a track set's array or an analysis cut short gave numpy's bare
    "Failed to read all data" or zipfile's "File is not a zip file", naming neither the
    file nor what to do."""
    npy, npz = tmp_path / "x01_y00.npy", tmp_path / "analysis.npz"
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    np.save(npy, a)
    np.savez(npz, a=a, b=a[:1])
    assert np.array_equal(read_npy(npy), a)
    assert set(read_npz(npz)) == {"a", "b"} and np.array_equal(read_npz(npz)["b"], a[:1])
    remedy = "if the workflow wrote it, delete it and run again to make it anew"
    for path, read in ((npy, read_npy), (npz, read_npz)):
        data = path.read_bytes()
        for damaged in (data[: len(data) // 2], b"", b"not numpy at all" * 10):
            path.write_bytes(damaged)
            with pytest.raises(ValueError, match=rf"{path}: not a readable numpy file "
                                                 rf"\(.*\); {remedy}"):
                read(path)
    with pytest.raises(FileNotFoundError):
        read_npy(tmp_path / "missing.npy")
    with pytest.raises(IsADirectoryError):  # not damage: no "delete it" advice
        read_npz(tmp_path)


def test_a_view_emptied_or_cut_is_named_before_it_is_copied(tmp_path: Path):
    """SIFT's jobs copy the views into a temporary folder; an emptied view failed there,
    named by its temporary copy. Now the view itself is named, with the remedy."""
    from plenocal.calib.reg_a.colmap import stage_images  # noqa: PLC0415

    view = tmp_path / "views" / "x00_y00" / "0_0.png"
    view.parent.mkdir(parents=True)
    write_image(view, np.full((20, 30, 3), 90, np.uint8))
    assert stage_images({"x00_y00/0_0": view}, tmp_path / "a") == ["x00_y00/0_0.png"]
    whole = view.read_bytes()
    for cut, words in ((b"", "is empty"), (whole[:-20], "is cut short")):
        view.write_bytes(cut)
        with pytest.raises(OSError, match=rf"{view}: the image of view 'x00_y00/0_0' "
                                          rf"{words}.*delete it and run again"):
            stage_images({"x00_y00/0_0": view}, tmp_path / "b")
