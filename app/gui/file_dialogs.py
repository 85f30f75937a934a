"""Open and save dialogs that start where the user last was.

Every file dialog of the app goes through :func:`open_file_name` or :func:`save_file_name`:
they start in the folder of the last file chosen (any dialog: one folder, remembered in the
settings under ``dialogs/last_folder``), else in ``fallback`` (e.g. the recordings folder),
else in the home folder, never in the working directory (which was the source tree).
A suggested file name is kept, in the remembered folder.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QFileDialog, QWidget

from app.gui.user_settings import create_settings

LAST_FOLDER_KEY = "dialogs/last_folder"

_settings: QSettings | None = None


def use_settings(settings: QSettings | None) -> None:
    """Remember the folder in ``settings`` (the main window's); None: the default file."""
    global _settings
    _settings = settings


def _store() -> QSettings:
    global _settings
    if _settings is None:
        _settings = create_settings()
    return _settings


def last_folder() -> Path | None:
    """The folder of the last file chosen in any dialog, if it still exists."""
    value = _store().value(LAST_FOLDER_KEY)
    if not isinstance(value, str) or not value:
        return None
    folder = Path(value)
    return folder if folder.is_dir() else None


def remember(path: str | Path) -> None:
    """Remember the folder of ``path`` (a chosen file) for the next dialog."""
    folder = Path(path).expanduser().resolve().parent
    settings = _store()
    settings.setValue(LAST_FOLDER_KEY, str(folder))
    settings.sync()


def start_path(suggested_name: str = "", fallback: Path | None = None) -> str:
    """Where a dialog opens: the last folder (else ``fallback`` if it exists, else home),
    with ``suggested_name`` (only its file name) in it."""
    folder = last_folder()
    if folder is None:
        folder = fallback if fallback is not None and fallback.is_dir() else Path.home()
    name = Path(suggested_name).name if suggested_name else ""
    return str(folder / name) if name else str(folder)


def open_file_name(
    parent: QWidget | None, caption: str, file_filter: str, fallback: Path | None = None
) -> str:
    """Ask for a file to open; "" if cancelled. The folder is remembered."""
    path, _chosen = QFileDialog.getOpenFileName(parent, caption, start_path("", fallback),
                                                file_filter)
    if path:
        remember(path)
    return path


def save_file_name(
    parent: QWidget | None, caption: str, suggested_name: str, file_filter: str,
    fallback: Path | None = None,
) -> tuple[str, str]:
    """Ask for a file to save to: (path, chosen filter); ("", "") if cancelled. The folder is
    remembered."""
    path, chosen = QFileDialog.getSaveFileName(
        parent, caption, start_path(suggested_name, fallback), file_filter)
    if path:
        remember(path)
    return path, chosen
