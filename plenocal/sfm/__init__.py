"""Structure-from-motion with pycolmap: registration A (Section II-B of the paper), the
COLMAP boundary conversions, and a synthetic capture for the tests."""
