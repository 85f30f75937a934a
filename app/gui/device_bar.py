"""The device bar: pick a device URL, connect or disconnect, see the stream's health."""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QComboBox, QLabel, QSizePolicy, QToolBar, QToolButton, QWidget

from app.core.devices import DeviceDescriptor
from app.gui import theme
from app.gui.elided_label import ElidedLabel

TOOLTIP_ROLE = Qt.ItemDataRole.ToolTipRole


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
        url = self.current_url()
        if url:
            self.set_state("connecting", f"Connecting to {url}…")
            self.connectRequested.emit(url)
