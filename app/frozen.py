"""Adjustments for running from a frozen (PyInstaller) bundle."""

from __future__ import annotations

import os
import sys


def prepare_frozen_environment() -> None:
    """Keep numba's compiled-filter cache in the user's cache directory, never in the bundle."""
    if not getattr(sys, "frozen", False):
        return
    from platformdirs import user_cache_dir

    os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(user_cache_dir("Inclinometer"), "numba"))
