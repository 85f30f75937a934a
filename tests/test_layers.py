"""Every module of the app sits in a layer of the import contracts (a new one cannot slip by)."""

from __future__ import annotations

import pkgutil
import tomllib
from pathlib import Path

import app

ROOT = Path(__file__).resolve().parents[1]


def test_every_top_level_module_of_app_is_in_a_layer():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    layered = set()
    for contract in config["contracts"]:
        if contract["type"] == "layers":
            for layer in contract["layers"]:
                layered.update(name.strip() for name in layer.replace("|", ":").split(":"))
    modules = {f"app.{m.name}" for m in pkgutil.iter_modules(app.__path__)}
    assert modules, "no modules found"
    assert modules <= layered, f"not in any layer: {sorted(modules - layered)}"
