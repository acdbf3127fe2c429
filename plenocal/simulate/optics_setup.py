"""Build the exact optics of the simulated camera from the config's ``simulate`` block."""

from __future__ import annotations

from plenocal.optics import PlenopticOptics


def type_focal_ratios(mla: dict) -> tuple[float, ...]:
    """Focal length of each lens type relative to ``mla.f_number``'s: (1,) for a
    single-focus MLA; (r0, 1, r2) for Raytrix's three types, ``mla.focal_ratios`` =
    [r0, r2] (type 1 is the middle one, whose F-number the paper's rule takes)."""
    n = int(mla["lens_types"])
    if n == 1:
        return (1.0,)
    if n == 3:
        r0, r2 = (float(r) for r in mla["focal_ratios"])
        return (r0, 1.0, r2)
    raise ValueError(f"simulate.mla.lens_types: 1 or 3, not {n}")


def optics_from_config(sim: dict) -> PlenopticOptics:
    """The simulated camera (lengths in metres) from a validated ``simulate`` block.

    Every lens type must image a plane on the set-up's side of the MLA sharply:
    kappa_i = s / f_i - 1 > 0 (Keplerian, f_i < s) or < 0 (Galilean, f_i > s); a
    ValueError names ``simulate.mla.focal_ratios`` otherwise."""
    optics = PlenopticOptics(
        focal_length=sim["main_lens"]["focal_length_mm"] / 1000.0,
        focus_distance=sim["main_lens"]["focus_distance_m"],
        mla_pitch=sim["mla"]["pitch_um"] * 1e-6,
        mla_f_number=sim["mla"]["f_number"],
        k=sim["mla"]["k"],
        pixel_size=sim["sensor"]["pixel_size_um"] * 1e-6,
        width=sim["sensor"]["width"],
        height=sim["sensor"]["height"],
        aperture_scale=sim["main_lens"]["aperture_scale"],
        kind=sim["mla"]["kind"],
        type_focal_ratios=type_focal_ratios(sim["mla"]),
    )
    sign = -1.0 if optics.galilean else 1.0
    for i in range(optics.lens_types):
        if sign * optics.type_kappa(i) <= 0:
            raise ValueError(
                f"simulate.mla.focal_ratios: lens type {i} (focal length "
                f"{optics.type_f(i) * 1e6:.1f} um, MLA-to-sensor distance "
                f"{optics.s * 1e6:.1f} um) images no {optics.kind} plane sharply; a "
                f"{optics.kind} type needs a focal length "
                f"{'below' if sign > 0 else 'above'} s (ratio "
                f"{'<' if sign > 0 else '>'} {optics.s / optics.f:.4f})")
    return optics
