"""The memory requests that grow with the capture (plenocal.job_memory), against
hand-computed cases."""

import pytest

from plenocal.job_memory import refine_mem_mb, refine_tracks_mem_mb, reprojection_mem_mb


def test_a_track_set_request_is_a_fixed_part_and_ten_times_the_database():
    assert refine_tracks_mem_mb(0) == 3000  # never under the 3 GB every geometry fits
    assert refine_tracks_mem_mb(167 * 10**6) == 3000  # the default array's: 500 + 1,670 MB
    assert refine_tracks_mem_mb(250 * 10**6) == 3000  # 500 + 2,500: the floor exactly
    assert refine_tracks_mem_mb(400 * 10**6) == 4500
    assert refine_tracks_mem_mb(400 * 10**6 + 1) == 4501  # rounded up, never down


def test_the_refine_request_is_a_fixed_part_and_thirty_times_the_track_sets():
    assert refine_mem_mb(0) == 3000
    assert refine_mem_mb(43 * 10**6) == 3000  # the default data's: 500 + 1,290 MB
    assert refine_mem_mb(100 * 10**6) == 3500


def test_table_is_triangulations_ask_for_a_fixed_part_and_six_times_the_database():
    assert reprojection_mem_mb(0) == 1500
    assert reprojection_mem_mb(207 * 10**6) == 1500  # dense: 200 + 1,242 MB
    assert reprojection_mem_mb(400 * 10**6) == 2600


def test_a_negative_size_is_refused():
    with pytest.raises(ValueError, match="-1 bytes"):
        refine_mem_mb(-1)
    with pytest.raises(ValueError, match="reprojection_mem_mb"):
        reprojection_mem_mb(-5)
