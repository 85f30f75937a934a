"""Menus and actions built from a table (napari's action tables are the model).

A window declares its menus as a list of entries (:mod:`app.gui.window_menus`): an
:class:`ActionSpec` (id, title, menu, callback name, shortcut, checkable, enabled at the
start, ...), a :class:`Separator`, a :class:`Submenu` or :class:`Generated` actions that exist
only at run time (the docks' toggles). :func:`build_menus` makes the menus in the order the
entries first name them, and connects each action to the callback found on the window by its
dotted name (``"open_recording"``, ``"session.requestTare"``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from PySide6.QtCore import SignalInstance
from PySide6.QtGui import QAction, QActionGroup, QKeySequence
from PySide6.QtWidgets import QMainWindow, QMenu

Shortcut = str | QKeySequence.StandardKey | None


@dataclass(frozen=True)
class ActionSpec:
    """One action: where it is, what it does, how it is reached."""

    id: str
    """Its key in :func:`build_menus`' result (``record_action`` becomes that attribute)."""
    title: str
    menu: str
    """Its menu's path of titles: ``"&File"``, ``"&View/&Theme"``."""
    callback: str
    """Dotted name of what it calls, from the window: ``"open_recording"``,
    ``"session.requestTare"`` (a signal is connected as it is)."""
    shortcut: Shortcut = None
    checkable: bool = False
    enabled: bool = True
    """Enabled at the start (the window changes it when its condition changes)."""
    tooltip: str = ""
    args: tuple[Any, ...] = ()
    """Passed to the callback (the checked state is not, unless ``passes_checked``)."""
    passes_checked: bool = False
    """The callback takes the checked state (``triggered(bool)``)."""
    on_toggle: bool = False
    """Call on ``toggled`` (any change of the checked state) instead of ``triggered``."""
    window_wide: bool = False
    """Also the window's own action: its shortcut works while the menu bar is hidden."""
    group: str = ""
    """Actions with the same group are exclusive (one checked)."""


@dataclass(frozen=True)
class Separator:
    menu: str


@dataclass(frozen=True)
class Submenu:
    """A submenu made here even before (or without) its first action."""

    menu: str


@dataclass(frozen=True)
class Generated:
    """Actions that only exist at run time: ``provider`` (dotted name, from the window)
    returns them, in order."""

    menu: str
    provider: str


Entry = ActionSpec | Separator | Submenu | Generated


def resolve(root: object, dotted: str) -> Any:
    """``root.a.b`` for ``"a.b"``."""
    target = root
    for part in dotted.split("."):
        target = getattr(target, part)
    return target


def _callback(target: Any, spec: ActionSpec) -> Callable[..., Any]:
    if isinstance(target, SignalInstance):
        if spec.args:
            return lambda _checked=False, s=target, a=spec.args: s.emit(*a)
        return target
    if spec.passes_checked or spec.on_toggle:
        return target
    return lambda _checked=False, f=target, a=spec.args: f(*a)


def make_action(window: QMainWindow, spec: ActionSpec) -> QAction:
    """The action of ``spec``, connected to its callback on ``window``."""
    action = QAction(spec.title, window)
    if spec.shortcut is not None:
        action.setShortcut(QKeySequence(spec.shortcut))
    if spec.checkable:
        action.setCheckable(True)
    if not spec.enabled:
        action.setEnabled(False)
    if spec.tooltip:
        action.setToolTip(spec.tooltip)
    signal = action.toggled if spec.on_toggle else action.triggered
    signal.connect(_callback(resolve(window, spec.callback), spec))
    return action


def build_menus(window: QMainWindow, entries: Sequence[Entry]) -> dict[str, QAction]:
    """Make ``window``'s menus from ``entries``; returns the actions by id."""
    menus: dict[str, QMenu] = {}
    groups: dict[str, QActionGroup] = {}
    actions: dict[str, QAction] = {}
    window_wide: list[QAction] = []

    def menu_of(path: str) -> QMenu:
        if path not in menus:
            parent, _, title = path.rpartition("/")
            menus[path] = (menu_of(parent).addMenu(title) if parent
                           else window.menuBar().addMenu(title))
        return menus[path]

    for entry in entries:
        menu = menu_of(entry.menu)
        if isinstance(entry, Separator):
            menu.addSeparator()
        elif isinstance(entry, Generated):
            for action in resolve(window, entry.provider)():
                menu.addAction(action)
        elif isinstance(entry, ActionSpec):
            action = make_action(window, entry)
            if entry.group:
                groups.setdefault(entry.group, QActionGroup(window)).addAction(action)
            menu.addAction(action)
            actions[entry.id] = action
            if entry.window_wide:
                window_wide.append(action)
    for action in window_wide:  # keep working while the menu bar is hidden (full screen)
        window.addAction(action)
    return actions
