"""The link decoder as it was at an earlier commit, loaded from git beside today's: how a host
built before a protocol extension reads the extended stream (the extensions' tests)."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parent.parent


def load_old_decoder(tmp_path: Path, commit: str, package: str) -> ModuleType:
    """``drivers/link/{decoder,protocol,framing}.py`` at ``commit`` as a package of its own
    (``package``), so it imports nothing of today's; returns its decoder module."""
    folder = tmp_path / package
    folder.mkdir()
    (folder / "__init__.py").write_text("")
    for name in ("decoder", "protocol", "framing"):
        source = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{commit}:drivers/link/{name}.py"],
            capture_output=True, text=True, check=True).stdout
        source = source.replace("from drivers.link import protocol",
                                f"from {package} import protocol")
        source = source.replace("from drivers.link.", f"from {package}.")
        (folder / f"{name}.py").write_text(source)
    sys.path.insert(0, str(tmp_path))
    try:
        return importlib.import_module(f"{package}.decoder")
    finally:
        sys.path.remove(str(tmp_path))
