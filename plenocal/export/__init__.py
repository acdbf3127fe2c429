"""Exports of a calibration: the plain cameras.json, the MPEG-I camera JSON (RVS, DERS,
IVDE, TMIV), a COLMAP sparse model, and 16-bit normalised-disparity depth maps."""
