"""Where the user's choices are remembered, and what happens when that file is damaged.

Settings are a QSettings INI file in the user's configuration directory
(``~/.config/Inclinometer/Inclinometer.ini`` on Linux), or the file named by the environment
variable ``INCLINOMETER_SETTINGS``. QSettings reads almost anything as INI, so the file is
checked first: if it is not text made of ``[section]`` and ``key=value`` lines, is larger than
:data:`MAX_SETTINGS_BYTES`, or holds a value of the wrong type (:data:`VALUE_KINDS`: the window
geometry must be bytes, a display setting a number, a section bounded JSON of an object,
:mod:`app.core.bounded_input`), it is moved aside (``NAME.corrupt-YYYYmmdd-HHMMSS``, never over
an earlier one), the defaults are used and the caller gets a message.

Parts of the app that keep their own configuration as a dict (the alarms, for instance)
register a section with :class:`SettingsSections`; it is stored as JSON under
``sections/NAME``, loaded when registered and saved on :meth:`SettingsSections.save_all`.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import stat
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6.QtCore import QByteArray, QSettings

from app.core.bounded_input import (
    InputTooLargeError,
    JsonInputError,
    NotRegularFileError,
    loads_json,
    read_bounded,
)

ORGANIZATION = "Inclinometer"
APPLICATION = "Inclinometer"
SETTINGS_ENV = "INCLINOMETER_SETTINGS"
"""Environment variable: the settings file to use instead of the user's."""

_LINE = re.compile(r"^\s*(\[[^\]]*\]|[^=\[\]][^=]*=.*|[;#].*)?\s*$")
MAX_SETTINGS_BYTES = 4 << 20
"""A settings file takes a few kB; a larger one is treated as damaged."""
VALUE_KINDS: dict[str, str] = {
    "geometry": "bytes", "window_state": "bytes",
    "filter": "text", "device_url": "text", "comparisons": "text", "unit": "text",
    "theme": "text",
    "averaging_s": "number", "range_deg": "number", "plot_window_s": "number",
}
"""The type each key the window reads must have; keys not listed are not read by it."""
JSON_PREFIXES = ("sections/", "filter_parameters/")
"""Keys under these hold JSON text of an object."""


def create_settings(path: str | os.PathLike[str] | None = None) -> QSettings:
    """The settings: ``path``, else ``$INCLINOMETER_SETTINGS``, else the user's INI file.

    A FIFO or a device in the file's place would block QSettings for ever (it reads the file
    when constructed): it is moved aside first, and :func:`check_settings` reports it.
    """
    chosen = path or os.environ.get(SETTINGS_ENV)
    problem = _move_aside_if_special(Path(chosen) if chosen else _default_ini_path())
    if chosen:
        settings = QSettings(str(chosen), QSettings.Format.IniFormat)
    else:
        ini, user = QSettings.Format.IniFormat, QSettings.Scope.UserScope
        settings = QSettings(ini, user, ORGANIZATION, APPLICATION)
    if problem:
        settings.setProperty(_PROBLEM, problem)
    return settings


_PROBLEM = "inclinometer_settings_problem"
"""QSettings property: what :func:`create_settings` found, for :func:`check_settings`."""


def _default_ini_path() -> Path | None:
    """Where QSettings keeps the user's INI file on Unix (None elsewhere: no FIFOs there)."""
    if os.name != "posix":
        return None
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return Path(base) / ORGANIZATION / f"{APPLICATION}.ini"


def _move_aside_if_special(path: Path | None) -> str | None:
    """Move a settings "file" that is a FIFO, a device or a folder aside; a message, or None."""
    try:
        if path is None or stat.S_ISREG(os.stat(path).st_mode):
            return None
    except OSError:
        return None  # absent (QSettings creates it) or unreadable (reported later)
    aside = move_aside(path)
    kept = f"it was moved to {aside}" if aside else "it could not be moved aside"
    return f"The settings file {path} is not a regular file; {kept}. The defaults are used."


def ini_problem(data: bytes) -> str | None:
    """Why ``data`` is not a settings INI file (None: it is one, or empty)."""
    if b"\x00" in data:
        return "it contains binary data"
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        return f"it is not UTF-8 text (byte {exc.start})"
    for number, line in enumerate(text.splitlines(), start=1):
        if not _LINE.match(line):
            shown = line if len(line) <= 40 else line[:40] + "…"
            return f"line {number} is neither [section] nor key=value: {shown!r}"
    return None


def value_problem(key: str, value: Any) -> str | None:
    """Why ``value`` cannot be the setting ``key`` (None: it can, or the key is not read)."""
    kind = VALUE_KINDS.get(key)
    if key.startswith(JSON_PREFIXES):
        kind = "json"
    if kind is None:
        return None
    if kind == "bytes":
        return None if isinstance(value, QByteArray | bytes) else "is not saved window data"
    if kind == "text":  # an unquoted "a,b" reads as a list of texts: harmless
        parts = value if isinstance(value, list) else [value]
        ok = all(isinstance(p, str) for p in parts) and sum(map(len, parts)) <= 4096
        return None if ok else "is not a short text"
    if kind == "number":
        try:
            number = float(value) if isinstance(value, str | int | float) else math.nan
        except ValueError:
            number = math.nan
        ok = (math.isfinite(number) and not isinstance(value, bool)
              and len(str(value)) <= 40)
        return None if ok else "is not a number"
    if not isinstance(value, str):
        return "is not JSON text"
    try:
        decoded = loads_json(value)
    except JsonInputError as exc:
        return str(exc)
    return None if isinstance(decoded, dict) else "is not a JSON object"


def check_settings(settings: QSettings) -> str | None:
    """Make sure ``settings`` reads a sound file; a damaged one is moved aside and the
    settings start empty (the defaults). Returns a message for the user, or None."""
    found = settings.property(_PROBLEM)
    if found:
        return str(found)
    path = Path(settings.fileName())
    try:
        data = read_bounded(path, MAX_SETTINGS_BYTES)
    except FileNotFoundError:
        return None
    except InputTooLargeError:
        data, problem = b"", f"it is larger than {MAX_SETTINGS_BYTES >> 20} MB"
    except NotRegularFileError as exc:
        return f"The settings file {path} cannot be used ({exc}); the defaults are used."
    except OSError as exc:
        return f"The settings file {path} could not be read ({exc}); the defaults are used."
    else:
        problem = ini_problem(data)
    if problem is None and settings.status() == QSettings.Status.FormatError:
        problem = "Qt could not parse it"
    if problem is None:
        problem = _values_problem(settings)
    if problem is None:
        return None
    aside = move_aside(path)
    kept = (f"it was kept as {aside}" if aside is not None
            else "it could not be moved aside and will be overwritten")
    settings.clear()
    settings.sync()
    return f"The settings file {path} was damaged ({problem}); {kept}. The defaults are used."


def _values_problem(settings: QSettings) -> str | None:
    """The first stored value of the wrong type, as a reason (None: all are sound)."""
    for key in settings.allKeys():
        try:
            value = settings.value(key)
        except (RuntimeError, TypeError, ValueError) as exc:  # a value Qt cannot convert
            return f"{_shown(key)} cannot be read ({exc})"
        reason = value_problem(key, value)
        if reason is not None:
            return f"{_shown(key)} {reason}"
    return None


def _shown(key: str) -> str:
    return repr(key if len(key) <= 40 else key[:40] + "…")


def move_aside(path: Path, *, copy: bool = False) -> Path | None:
    """Rename (or copy) ``path`` to ``NAME.corrupt-<time>``, never over an existing file;
    the new name, or None when that fails."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for attempt in range(100):
        target = path.with_name(f"{path.name}.corrupt-{stamp}" + (f"-{attempt}" if attempt
                                                                   else ""))
        try:
            if copy:
                with open(path, "rb") as source, open(target, "xb") as out:
                    shutil.copyfileobj(source, out)
            else:
                if target.exists():
                    continue
                os.rename(path, target)
        except FileExistsError:
            continue
        except OSError:
            return None
        return target
    return None


def read_json(settings: QSettings, key: str) -> Any:
    """A value stored as JSON text under ``key`` (None if absent or not JSON)."""
    text = settings.value(key)
    if not isinstance(text, str) or not text:
        return None
    try:
        return loads_json(text)
    except ValueError:
        return None


def write_json(settings: QSettings, key: str, value: Any) -> None:
    """Store ``value`` as JSON text under ``key`` (numbers that numpy made become floats)."""
    settings.setValue(key, json.dumps(value, default=float, sort_keys=True))


class SettingsSections:
    """The app's one way to its settings: named sections, and single keys.

    Sections are named parts of the settings that a component saves and loads as a dict.

    Register with ``sections.register("alarms", config.to_dict, load)``: ``load(dict)`` is
    called at once with the stored dict, if there is one; a ``load`` that raises
    ``ValueError``, ``KeyError`` or ``TypeError`` leaves the component as it is and
    ``report`` gets a message. Every registered section is saved by :meth:`save_all` (the
    main window calls it when it closes) or one at a time by :meth:`save`.

    Single keys (the window's ``unit``, ``geometry``, ``filter_parameters/NAME``, ...: the
    names :data:`VALUE_KINDS` lists, as they always were) are read with :meth:`value`,
    :meth:`number`, :meth:`text` and :meth:`json`, and written with :meth:`set_value` and
    :meth:`set_json`.
    """

    PREFIX = "sections/"

    def __init__(self, settings: QSettings, report: Callable[[str], None]) -> None:
        self.settings = settings
        self.report = report
        self._savers: dict[str, Callable[[], dict]] = {}

    def register(
        self, name: str, save: Callable[[], dict], load: Callable[[dict], None]
    ) -> bool:
        """Add a section; returns whether a stored one was loaded."""
        self._savers[name] = save
        stored = read_json(self.settings, self.PREFIX + name)
        if stored is None:
            return False
        if not isinstance(stored, dict):
            self.report(f"Remembered {name} settings are not valid; the defaults are "
                        f"used{self._kept()}.")
            return False
        try:
            load(stored)
        except (ValueError, KeyError, TypeError, RecursionError) as exc:
            self.report(f"Remembered {name} settings are not valid ({str(exc)[:200]}); the "
                        f"defaults are used{self._kept()}.")
            return False
        return True

    def _kept(self) -> str:
        """A copy of the settings file beside it, before the defaults are saved over the bad
        section (nothing is lost): ``"; a copy ... was kept as NAME"``."""
        self.settings.sync()
        path = Path(self.settings.fileName())
        if not path.is_file():
            return ""
        copy = move_aside(path, copy=True)
        return f"; a copy of the settings file was kept as {copy}" if copy else ""

    def names(self) -> list[str]:
        """The registered sections."""
        return list(self._savers)

    def save(self, name: str) -> None:
        """Store one section now."""
        write_json(self.settings, self.PREFIX + name, self._savers[name]())

    def save_all(self) -> None:
        """Store every registered section."""
        for name in self._savers:
            self.save(name)

    # -- single keys --------------------------------------------------------------------------
    def value(self, key: str) -> Any:
        """The stored value of ``key`` as Qt reads it (None: absent)."""
        return self.settings.value(key)

    def has(self, key: str) -> bool:
        return self.settings.value(key) is not None

    def text(self, key: str, default: str) -> str:
        """``key`` as text (``default`` when absent)."""
        return str(self.settings.value(key, default))

    def number(self, key: str, default: float, kind: type = float) -> Any:
        """``key`` as ``kind`` (int or float); ``default`` when absent or not a number."""
        try:
            return kind(self.settings.value(key, default))
        except (TypeError, ValueError):
            return default

    def flag(self, key: str, default: bool) -> bool:
        """``key`` as a yes/no (an INI file keeps ``true``/``false`` as text); ``default``
        when absent or neither."""
        value = self.settings.value(key, default)
        if isinstance(value, bool):
            return value
        text = str(value).strip().lower()
        return True if text in ("true", "1") else False if text in ("false", "0") else default

    def json(self, key: str) -> Any:
        """``key`` stored as JSON text (None if absent or not JSON)."""
        return read_json(self.settings, key)

    def set_value(self, key: str, value: Any) -> None:
        self.settings.setValue(key, value)

    def set_json(self, key: str, value: Any) -> None:
        write_json(self.settings, key, value)

    def file_name(self) -> str:
        """Where the settings are kept."""
        return self.settings.fileName()

    def sync(self) -> None:
        """Write everything to the file now."""
        self.settings.sync()
