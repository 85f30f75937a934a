"""The device bar: pick a device URL, connect or disconnect, see the stream's health."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QModelIndex, QObject, QPersistentModelIndex, Qt, Signal
from PySide6.QtGui import QKeyEvent, QStandardItem, QStandardItemModel
from PySide6.QtWidgets import (
    QComboBox,
    QCompleter,
    QLabel,
    QSizePolicy,
    QToolBar,
    QToolButton,
    QWidget,
)

from app.core.devices import DeviceDescriptor
from app.gui import theme
from app.gui.elided_label import ElidedLabel
from app.services.devices import option_hints

TOOLTIP_ROLE = Qt.ItemDataRole.ToolTipRole
HELP_ROLE = Qt.ItemDataRole.UserRole + 1
"""An option's help, one line (shown beside the device field while it is highlighted)."""


def option_tooltip(row: dict[str, object]) -> str:
    """An option's help with its type, default and range (``devices --options`` in one text)."""
    limits = " ".join(str(part) for part in (row["limits"], row["unit"]) if part)
    default = row["default"]
    facts = [str(row["type"])]
    if default is not None:
        facts.append(f"default {default}")
    if limits:
        facts.append(limits)
    return f"{row['name']}: {row['help']}\n({', '.join(facts)})"


class UrlOptionCompleter(QCompleter):
    """Completes the option name after a device URL's last ``?`` or ``&`` with the options the
    URL's driver declares (their help as tooltip); :meth:`offer` says whether it applies."""

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._model = QStandardItemModel(self)
        self.setModel(self._model)
        self.setCaseSensitivity(Qt.CaseSensitivity.CaseInsensitive)
        self.setCompletionMode(QCompleter.CompletionMode.PopupCompletion)
        self._head = ""
        self._offered_for = ""
        self.choosing = False
        """True while the popup's Return or Enter chooses an option (the line edit sees that
        key too, after the choice: it must not connect)."""

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        """Note a Return or Enter in the popup that chooses an option."""
        choosing = (watched is self.popup() and event.type() == QEvent.Type.KeyPress
                    and isinstance(event, QKeyEvent)
                    and event.key() in (Qt.Key.Key_Return, Qt.Key.Key_Enter)
                    and self.popup().currentIndex().isValid())
        self.choosing = choosing
        try:
            return super().eventFilter(watched, event)
        finally:
            self.choosing = False

    def offer(self, text: str) -> bool:
        """Fill the list for ``text``; False when it is no URL with a query yet or its scheme
        names no driver."""
        cut = max(text.rfind("?"), text.rfind("&"))
        if "?" not in text:
            return False
        self._head = text[: cut + 1]
        if self._head != self._offered_for:  # the query so far may pick options (a scenario)
            self._offered_for = self._head
            self._model.clear()
            for row in option_hints(self._head):
                item = QStandardItem(f"{row['name']}=")
                item.setData(option_tooltip(row), TOOLTIP_ROLE)
                item.setData(f"{row['name']}: {row['help']}", HELP_ROLE)
                self._model.appendRow(item)
        return self._model.rowCount() > 0

    def splitPath(self, path: str) -> list[str]:
        """Complete only the option being typed (after the last ? or &)."""
        return [path[max(path.rfind("?"), path.rfind("&")) + 1 :]]

    def pathFromIndex(self, index: QModelIndex | QPersistentModelIndex) -> str:
        """The URL so far with the chosen ``name=``."""
        return self._head + str(index.data())


class DeviceBar(QToolBar):
    """Toolbar with the device chooser, a connect toggle and a status lamp."""

    connectRequested = Signal(str)
    disconnectRequested = Signal()
    refreshRequested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("Device", parent)
        self.setObjectName("deviceBar")
        self.setMovable(False)
        self.addWidget(QLabel(" Device "))
        self.device_combo = QComboBox()
        self.device_combo.setEditable(True)
        self.device_combo.setMinimumContentsLength(28)
        self.device_combo.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
        self.device_combo.setInsertPolicy(QComboBox.InsertPolicy.NoInsert)
        self.device_combo.setToolTip(
            "A device URL: sim://SCENARIO for the simulator; serial ports appear here when found"
        )
        self.device_combo.lineEdit().returnPressed.connect(self._on_connect_clicked)
        self._url_completer = self.device_combo.completer()
        self._url_completer.setParent(self)  # the line edit deletes a replaced child completer
        self.option_completer = UrlOptionCompleter(self)
        self.option_completer.highlighted[QModelIndex].connect(self._show_option_help)
        self.device_combo.lineEdit().textEdited.connect(self._complete_options)
        self.device_combo.currentIndexChanged.connect(self._show_description)
        self.addWidget(self.device_combo)

        self.refresh_button = QToolButton()
        self.refresh_button.setText("⟳")
        self.refresh_button.setToolTip("Look for devices again")
        self.refresh_button.clicked.connect(self.refreshRequested)
        self.addWidget(self.refresh_button)

        self.connect_button = QToolButton()
        self.connect_button.setObjectName("connectButton")
        self.connect_button.setCheckable(True)
        self.connect_button.setText("Connect")
        self.connect_button.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextOnly)
        self.connect_button.clicked.connect(self._on_connect_clicked)
        self.addWidget(self.connect_button)

        self.description_label = QLabel()
        self.description_label.setObjectName("dimLabel")
        self.addWidget(self.description_label)

        spacer = QWidget()
        spacer.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Preferred)
        self.addWidget(spacer)

        self.lamp = QLabel("●")
        self.status_label = ElidedLabel("Disconnected")
        self.status_label.setObjectName("streamStatus")
        self.addWidget(self.lamp)
        self.addWidget(self.status_label)
        self.set_state("disconnected")

    # -- content ----------------------------------------------------------------------------
    def set_devices(self, devices: list[DeviceDescriptor], current_url: str | None = None) -> None:
        """Fill the chooser; keep ``current_url`` (or the typed text) selected."""
        keep = current_url or self.current_url()
        self.device_combo.blockSignals(True)
        self.device_combo.clear()
        for descriptor in devices:
            self.device_combo.addItem(descriptor.url, descriptor.description)
            index = self.device_combo.count() - 1
            self.device_combo.setItemData(index, descriptor.description, TOOLTIP_ROLE)
        self.device_combo.blockSignals(False)
        self.select_url(keep)

    def select_url(self, url: str) -> None:
        index = self.device_combo.findText(url)
        if index >= 0:
            self.device_combo.setCurrentIndex(index)
        else:
            self.device_combo.setEditText(url)
        self._show_description()

    def current_url(self) -> str:
        return self.device_combo.currentText().strip()

    def _complete_options(self, text: str) -> None:
        """After a ``?`` or ``&``, offer the URL's options; else the devices' URLs."""
        offered = self.option_completer.offer(text)
        wanted = self.option_completer if offered else self._url_completer
        line = self.device_combo.lineEdit()
        if line.completer() is not wanted:  # the line edit's, not the combo's: the combo would
            line.setCompleter(wanted)  # take a chosen option for one of its items
        if offered and "=" not in self.option_completer.splitPath(text)[0]:
            self.option_completer.setCompletionPrefix(self.option_completer.splitPath(text)[0])
            self.option_completer.complete()

    def _show_option_help(self, index: QModelIndex) -> None:
        self.description_label.setText(f"  {index.data(HELP_ROLE)}")

    def _show_description(self) -> None:
        index = self.device_combo.findText(self.current_url())
        text = self.device_combo.itemData(index) if index >= 0 else ""
        self.description_label.setText(f"  {text}" if text else "")

    # -- state ------------------------------------------------------------------------------
    def set_state(self, state: str, text: str | None = None) -> None:
        """Show a state: disconnected, connecting, streaming, stalled or error."""
        colours = {
            "disconnected": theme.TEXT_DISABLED, "connecting": theme.WARN_AMBER,
            "streaming": theme.OK_GREEN, "stalled": theme.WARN_AMBER, "error": theme.ALARM_RED,
        }
        # Called with every status: only what changed is touched (a new stylesheet
        # re-polishes the lamp, a new button text relayouts the bar).
        style = f"color: {colours[state]}; font-size: 14pt;"
        if self.lamp.styleSheet() != style:
            self.lamp.setStyleSheet(style)
        live = state in ("connecting", "streaming", "stalled")
        if self.connect_button.isChecked() != live:
            self.connect_button.setChecked(live)
        label = "Disconnect" if live else "Connect"
        if self.connect_button.text() != label:
            self.connect_button.setText(label)
        self.status_label.setText(text or state.capitalize())
        # Never elided: the toolbar gives it at least its widest text so far (also after a
        # theme changed its font).
        widest = self.status_label.sizeHint().width()
        if self.status_label.minimumWidth() < widest:
            self.status_label.setMinimumWidth(widest)

    def _on_connect_clicked(self) -> None:
        if self.connect_button.text() == "Disconnect" and self.sender() is self.connect_button:
            self.disconnectRequested.emit()
            return
        if self.option_completer.choosing:  # the Return that chose an option: a value
            return  # comes next
        url = self.current_url()
        if url:
            self.set_state("connecting", f"Connecting to {url}…")
            self.connectRequested.emit(url)
