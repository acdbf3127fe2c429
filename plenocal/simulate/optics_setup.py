"""Build the exact optics of the simulated camera from the config's ``simulate`` block."""

from __future__ import annotations

from plenocal.optics import PlenopticOptics


def optics_from_config(sim: dict) -> PlenopticOptics:
    """The simulated camera (lengths in metres) from a validated ``simulate`` block."""
    return PlenopticOptics(
        focal_length=sim["main_lens"]["focal_length_mm"] / 1000.0,
        focus_distance=sim["main_lens"]["focus_distance_m"],
        mla_pitch=sim["mla"]["pitch_um"] * 1e-6,
        mla_f_number=sim["mla"]["f_number"],
        k=sim["mla"]["k"],
        pixel_size=sim["sensor"]["pixel_size_um"] * 1e-6,
        width=sim["sensor"]["width"],
        height=sim["sensor"]["height"],
        aperture_scale=sim["main_lens"]["aperture_scale"],
    )
