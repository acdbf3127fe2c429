"""Shot folders a dataset's config no longer names (plenocal.artifacts.stale_shots)."""

from __future__ import annotations

from pathlib import Path

from plenocal.artifacts.stale_shots import stale_shot_folders, stale_shot_message


def test_only_shot_folders_the_config_does_not_name_are_stale(tmp_path: Path):
    views = tmp_path / "results/d/views"
    for name in ("x00_y00", "x01_y00", "hand00", "hand03", "mine", ".staging"):
        (views / name).mkdir(parents=True)
    (views / "convert_setup.json").write_text("{}")
    (views / "x05_y05").write_text("a file, not a folder")
    stale = stale_shot_folders(views, ["x00_y00", "hand00"])
    assert [p.name for p in stale] == ["hand03", "x01_y00"]
    assert stale_shot_folders(views, ["x00_y00", "x01_y00", "hand00", "hand03"]) == []
    assert stale_shot_folders(tmp_path / "no/such/folder", ["x00_y00"]) == []


def test_the_message_names_the_folders_and_how_to_remove_them(tmp_path: Path):
    views = tmp_path / "my results/d/views"
    folders = [views / "hand03", views / "x01_y00"]
    text = stale_shot_message("d", folders)
    assert text.startswith("dataset d: 2 shot folder(s) under ")
    assert "(hand03, x01_y00)" in text
    assert text.endswith(f"rm -r '{views}/hand03' '{views}/x01_y00'")
