"""Registration A (Section II-B of the paper): structure from motion of the central views
with pycolmap.

* :mod:`.sfm` - features, matching and mapping of the central views (``reg_a.json``).
* :mod:`.viewdb` - the COLMAP database of every view (Table I's pairs, the baselines).
* :mod:`.colmap` - the COLMAP boundary: image staging, SIFT, matching, and the
  conversions to and from COLMAP's reconstruction.
"""
