"""Shot folders a dataset's config no longer names (plenocal.artifacts.stale_shots)."""

from __future__ import annotations

from pathlib import Path

from plenocal.artifacts.stale_shots import (
    SHOT_FOLDERS,
    stale_dataset_folders,
    stale_shot_folders,
    stale_shot_message,
)


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


def test_every_per_shot_folder_of_a_dataset_is_looked_at(tmp_path: Path):
    d = tmp_path / "results/d"
    for sub in SHOT_FOLDERS:
        for name in ("x00_y00", "hand03"):
            (d / sub / name).mkdir(parents=True)
    (d / "depth/a/x07_y07").mkdir(parents=True)  # not a folder of shots: left out
    stale = stale_dataset_folders(d, ["x00_y00"])
    assert stale == [d / sub / "hand03" for sub in SHOT_FOLDERS]
    assert stale_dataset_folders(d, ["x00_y00", "hand03"]) == []
    assert stale_dataset_folders(tmp_path / "no/such/dataset", ["x00_y00"]) == []


def test_the_message_names_the_shots_their_folders_and_how_to_remove_them(tmp_path: Path):
    d = tmp_path / "my results/d"
    folders = [d / "views/hand03", d / "views/x01_y00", d / "depth/views/hand03"]
    text = stale_shot_message("d", folders)
    assert text.startswith("dataset d: 3 shot folder(s) that the config no longer names "
                           f"(hand03, x01_y00) under {d}/views/, {d}/depth/views/: ")
    assert text.endswith(f"rm -r '{d}/views/hand03' '{d}/views/x01_y00' "
                         f"'{d}/depth/views/hand03'")
