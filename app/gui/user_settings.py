"""Where the user's choices are remembered, and what happens when that file is damaged.

Settings are a QSettings INI file in the user's configuration directory
(``~/.config/Inclinometer/Inclinometer.ini`` on Linux), or the file named by the environment
variable ``INCLINOMETER_SETTINGS``. QSettings reads almost anything as INI, so the file is
checked first: if it is not text made of ``[section]`` and ``key=value`` lines, it is moved
aside (``NAME.corrupt-YYYYmmdd-HHMMSS``), the defaults are used and the caller gets a message.

Parts of the app that keep their own configuration as a dict (the alarms, for instance)
register a section with :class:`SettingsSections`; it is stored as JSON under
``sections/NAME``, loaded when registered and saved on :meth:`SettingsSections.save_all`.
"""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6.QtCore import QSettings

ORGANIZATION = "Inclinometer"
APPLICATION = "Inclinometer"
SETTINGS_ENV = "INCLINOMETER_SETTINGS"
"""Environment variable: the settings file to use instead of the user's."""

_LINE = re.compile(r"^\s*(\[[^\]]*\]|[^=\[\]][^=]*=.*|[;#].*)?\s*$")


def create_settings(path: str | os.PathLike[str] | None = None) -> QSettings:
    """The settings: ``path``, else ``$INCLINOMETER_SETTINGS``, else the user's INI file."""
    chosen = path or os.environ.get(SETTINGS_ENV)
    if chosen:
        return QSettings(str(chosen), QSettings.Format.IniFormat)
    ini, user = QSettings.Format.IniFormat, QSettings.Scope.UserScope
    return QSettings(ini, user, ORGANIZATION, APPLICATION)


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


def check_settings(settings: QSettings) -> str | None:
    """Make sure ``settings`` reads a sound file; a damaged one is moved aside and the
    settings start empty (the defaults). Returns a message for the user, or None."""
    path = Path(settings.fileName())
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        return f"The settings file {path} could not be read ({exc}); the defaults are used."
    problem = ini_problem(data)
    if problem is None and settings.status() == QSettings.Status.FormatError:
        problem = "Qt could not parse it"
    if problem is None:
        return None
    aside = path.with_name(f"{path.name}.corrupt-{time.strftime('%Y%m%d-%H%M%S')}")
    try:
        os.replace(path, aside)
        kept = f"it was kept as {aside}"
    except OSError as exc:
        kept = f"it could not be moved aside ({exc}) and will be overwritten"
    settings.clear()
    settings.sync()
    return f"The settings file {path} was damaged ({problem}); {kept}. The defaults are used."


def read_json(settings: QSettings, key: str) -> Any:
    """A value stored as JSON text under ``key`` (None if absent or not JSON)."""
    text = settings.value(key)
    if not isinstance(text, str) or not text:
        return None
    try:
        return json.loads(text)
    except ValueError:
        return None


def write_json(settings: QSettings, key: str, value: Any) -> None:
    """Store ``value`` as JSON text under ``key`` (numbers that numpy made become floats)."""
    settings.setValue(key, json.dumps(value, default=float, sort_keys=True))


class SettingsSections:
    """Named parts of the settings that a component saves and loads as a dict.

    Register with ``sections.register("alarms", config.to_dict, load)``: ``load(dict)`` is
    called at once with the stored dict, if there is one; a ``load`` that raises
    ``ValueError``, ``KeyError`` or ``TypeError`` leaves the component as it is and
    ``report`` gets a message. Every registered section is saved by :meth:`save_all` (the
    main window calls it when it closes) or one at a time by :meth:`save`.
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
            self.report(f"Remembered {name} settings are not valid; the defaults are used.")
            return False
        try:
            load(stored)
        except (ValueError, KeyError, TypeError) as exc:
            self.report(f"Remembered {name} settings are not valid ({exc}); the defaults "
                        "are used.")
            return False
        return True

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
