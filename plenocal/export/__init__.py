"""Exports of a calibration: the MPEG-I camera JSON (RVS, DERS, IVDE, TMIV), a COLMAP
sparse model, and 16-bit normalised-disparity depth maps (the plain cameras.json is
plenocal.artifacts.cameras)."""
