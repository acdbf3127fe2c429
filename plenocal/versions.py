"""The versions that decide the outputs' bytes: plenocal's own and those of the libraries
pyproject.toml pins exactly (the same inputs give the same bytes only with the same
versions). ``plenocal --version`` prints :func:`version_text`; the report ends with it."""
from __future__ import annotations

import sys

#: the libraries whose versions decide the outputs' bytes, named beside plenocal's (deflate:
#: every PNG's stream; scikit-image: the photographs the simulator's textures are cut from)
VERSIONED = ("numpy", "opencv-python-headless", "pycolmap", "scipy", "numba", "deflate",
             "scikit-image", "snakemake")


def installed_version(name: str) -> str:
    """The installed version of the distribution ``name`` (its metadata: nothing is
    imported), or "not installed"."""
    from importlib.metadata import PackageNotFoundError, version  # noqa: PLC0415

    try:
        return version(name)
    except PackageNotFoundError:
        return "not installed"


def version_text() -> str:
    """``plenocal <version> (numpy <v>, ...; Python <v>)``, on one line: what a methods
    section or a bug report should quote."""
    libs = ", ".join(f"{name} {installed_version(name)}" for name in VERSIONED)
    return f"plenocal {installed_version('plenocal')} ({libs}; Python {sys.version.split()[0]})"
