"""Adjustments for running from a frozen (PyInstaller) bundle; nothing happens otherwise.

Called by ``packaging/launch.py`` before anything imports numba or Qt:

- numba's compiled-filter cache goes to the user's cache directory
  (``~/.cache/Inclinometer/numba`` on Linux, ``%LOCALAPPDATA%\\Inclinometer\\Cache\\numba`` on
  Windows, ``~/Library/Caches/Inclinometer/numba`` on macOS): the bundle may be read-only
  (``/opt``, ``Program Files``, a signed ``.app``) and must never be written to. numba reads
  the variable once, at import.
- no ``.pyc`` is written into the bundle: ``app`` ships as ``.py`` files (see the spec) and
  compiles in about 0.2 s at each start.
- a windowed Windows executable has no stdout or stderr (``None``): anything that prints
  (numba's warnings, argparse, a traceback) would raise; they go to the null device instead.

Settings, calibration profiles and recordings already live under the platform's user
directories (``platformdirs`` and ``QSettings``), frozen or not; resources are read with
``importlib.resources``, which works from the bundle as from a wheel.
"""

from __future__ import annotations

import os
import sys

APP_NAME = "Inclinometer"


def numba_cache_dir() -> str:
    """Where a frozen app keeps numba's cache (the user's cache directory)."""
    from platformdirs import user_cache_dir

    return os.path.join(user_cache_dir(APP_NAME, appauthor=False), "numba")


def prepare_frozen_environment() -> None:
    """Point numba's cache at the user cache; give a windowed app somewhere to print."""
    if not getattr(sys, "frozen", False):
        return
    os.environ.setdefault("NUMBA_CACHE_DIR", numba_cache_dir())
    sys.dont_write_bytecode = True
    for name in ("stdout", "stderr"):
        if getattr(sys, name) is None:
            setattr(sys, name, open(os.devnull, "w", encoding="utf-8"))  # noqa: SIM115
