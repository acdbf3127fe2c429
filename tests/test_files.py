"""plenocal.io.files: a run's outputs staged and moved into place (nothing half-written,
nothing of the previous run lost on a failure)."""

from __future__ import annotations

from pathlib import Path

import pytest

from plenocal.io.files import STAGE_PREFIX, staged_outputs


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
