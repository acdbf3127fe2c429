"""Floats rounded before they are written, so that a file is the same bytes run after run
where the computation behind it moves its last bits (the grid check's figures, the refined
focal length's deviation)."""

from __future__ import annotations

import math


def round_floats(value, digits: int, decimals: bool = False):
    """``value`` with every float (in nested dicts, lists and tuples) rounded to
    ``digits`` significant digits, or to ``digits`` decimals where ``decimals``; other
    values unchanged (-0.0 written as 0.0)."""
    if isinstance(value, float):
        if not math.isfinite(value):
            return value
        return (round(value, digits) if decimals else float(f"{value:.{digits}g}")) + 0.0
    if isinstance(value, dict):
        return {k: round_floats(v, digits, decimals) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(round_floats(v, digits, decimals) for v in value)
    return value
