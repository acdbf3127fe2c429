"""The converter's error type."""

from __future__ import annotations


class ConvertError(ValueError):
    """Input the converter cannot use; the message names the file and what to try."""
