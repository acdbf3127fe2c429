"""The command line's output folder holds one conversion (plenocal.convert.outfolder):
which earlier files stop a run, and which may stay."""

from __future__ import annotations

from pathlib import Path

import pytest

from plenocal.convert.errors import ConvertError
from plenocal.convert.outfolder import (
    check_output_folder,
    recording_claims,
    stale_view_videos,
    still_claims,
)
from plenocal.names import view_names


def _still(folder: Path, n: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name in [f"{v}.png" for v in view_names(n)] + ["patch_size.npy", "patch_size.png",
                                                       "disparity.json"]:
        (folder / name).write_bytes(b"x")


def _video(folder: Path, n: int, frames: range, fmt: str, size: str = "64x48") -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("convert_setup.json", "video.json"):
        (folder / name).write_text("{}")
    if fmt == "yuv":
        for v in view_names(n):
            (folder / f"v_{v}_{size}_10bit_yuv420p10le.yuv").write_bytes(b"")
        return
    for k in frames:
        _still(folder / f"frame_{k:05d}", n)


def test_a_still_of_fewer_views_over_more_is_refused_naming_the_files(tmp_path):
    _still(tmp_path, 5)
    with pytest.raises(ConvertError) as err:
        check_output_folder(tmp_path, still_claims(3), "3 x 3 views of one image")
    msg = str(err.value)
    assert msg.startswith(f"{tmp_path}: holds 0_3.png, 0_4.png, 1_3.png, 1_4.png, ... "
                          "(16 in all) from an earlier conversion")
    assert "3 x 3 views of one image" in msg and "-o" in msg


def test_a_still_over_the_same_or_fewer_views_and_foreign_files_pass(tmp_path):
    _still(tmp_path, 3)
    (tmp_path / "notes.txt").write_text("mine")
    (tmp_path / "lenslet.png").write_bytes(b"x")  # the input beside its views
    (tmp_path / "v000.png").write_bytes(b"x")  # TLCT's name, not ours
    check_output_folder(tmp_path, still_claims(3), "3 x 3")
    check_output_folder(tmp_path, still_claims(5), "5 x 5")
    check_output_folder(tmp_path / "absent", still_claims(5), "5 x 5")


def test_a_still_and_a_recording_do_not_share_a_folder(tmp_path):
    _video(tmp_path / "png", 3, range(2), "png")
    _video(tmp_path / "yuv", 3, range(2), "yuv")
    for kind in ("png", "yuv"):
        with pytest.raises(ConvertError, match="convert_setup.json"):
            check_output_folder(tmp_path / kind, still_claims(3), "3 x 3")
    _still(tmp_path / "still", 3)
    for fmt in ("png", "yuv"):
        with pytest.raises(ConvertError, match=r"holds 0_0\.png, 0_1\.png"):
            check_output_folder(tmp_path / "still", recording_claims(3, range(2), fmt), fmt,
                                n_views=3 if fmt == "png" else None)


def test_a_recording_in_chunks_of_frames_shares_its_folder(tmp_path):
    """Frame folders of other frames and the same view set stay (``--frames`` in chunks);
    of another view set (fewer or more views), they stop the run; a yuv run over png
    frames stops too."""
    _video(tmp_path, 3, range(0, 4), "png")
    check_output_folder(tmp_path, recording_claims(3, range(4, 8), "png"), "png", n_views=3)
    # frames 0..3 made again: replaced, whatever their views were
    check_output_folder(tmp_path, recording_claims(5, range(0, 8), "png"), "png", n_views=5)
    for n in (1, 5):
        with pytest.raises(ConvertError, match=r"holds frame_00000 \(3 x 3 views\), "
                                               r"frame_00001 \(3 x 3 views\)"):
            check_output_folder(tmp_path, recording_claims(n, range(4, 8), "png"), "png",
                                n_views=n)
    with pytest.raises(ConvertError, match="frame_00000"):
        check_output_folder(tmp_path, recording_claims(3, range(4, 8), "yuv"), "yuv")


def test_view_videos_of_another_view_set_stop_and_of_another_size_are_replaced(tmp_path):
    _video(tmp_path, 5, range(1), "yuv", size="64x48")
    with pytest.raises(ConvertError, match=r"v_0_3_64x48"):
        check_output_folder(tmp_path, recording_claims(3, range(1), "yuv"), "yuv")
    check_output_folder(tmp_path, recording_claims(5, range(1), "yuv"), "yuv")
    written = {f"v_{v}_66x50_10bit_yuv420p10le.yuv" for v in view_names(5)}
    for name in written:
        (tmp_path / name).write_bytes(b"")
    stale = stale_view_videos(tmp_path, written)
    assert [p.name for p in stale] == sorted(f"v_{v}_64x48_10bit_yuv420p10le.yuv"
                                             for v in view_names(5))
    # a run of fewer views leaves the others' files alone (the check refused it before)
    assert len(stale_view_videos(tmp_path, {"v_1_1_66x50_10bit_yuv420p10le.yuv"})) == 1
