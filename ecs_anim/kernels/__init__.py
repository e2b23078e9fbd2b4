"""The tick's compiled kernels (numba, DESIGN §7): one module per system, over the store's arrays.

Each kernel writes its results in place and mirrors a numpy function of the package, which stays
as the reference the tests compare it with (to 1e-9 m). ``vec`` holds the scalar helpers they
share: 3-vectors as tuples, frames as tuples of their three axes.

Compiled code is cached in the user's cache folder (``$XDG_CACHE_HOME/ecs_anim/numba``, else
``~/.cache/ecs_anim/numba``) unless ``NUMBA_CACHE_DIR`` says where: the first run compiles (tens
of seconds), later ones load in a fraction of a second. This must be set before numba is
imported, so the package imports its kernels only through here.
"""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """Where numba keeps the compiled kernels."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    if given:
        return Path(given)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "ecs_anim" / "numba"


os.environ.setdefault("NUMBA_CACHE_DIR", str(cache_dir()))
# The batch runner forks worker processes after kernels ran in the parent: GNU OpenMP (numba's
# first choice here) then kills the child, so take a fork-safe threading layer (workqueue here).
os.environ.setdefault("NUMBA_THREADING_LAYER", "forksafe")
