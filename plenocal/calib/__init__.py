"""The calibration of the paper, stage by stage (Sections II-B to II-D).

* :mod:`.reg_a` - registration A (Section II-B): structure from motion of the central
  views of every shot with pycolmap, one shared focal length ``F_m``.
* :mod:`.reg_b` - registration B (Section II-C, Eqs. 1-4): the N x N subaperture set of
  one camera from its datasheet and the converter's disparity range.
* :mod:`.scale` - the scale ratio ``r`` between A and the depth of B (Eq. 5).
* :mod:`.merge` - every view of every shot in A's frame at metric scale (Eq. 6).
"""
