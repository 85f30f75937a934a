"""Typed device errors. Each message is written for the user who will read it in the GUI."""


class DeviceError(Exception):
    """Base class of every error a driver raises."""


class DeviceUrlError(DeviceError):
    """The device URL is malformed, or names an unknown scheme or option."""


class DeviceOpenError(DeviceError):
    """The device could not be opened (missing, busy, permission denied, wrong protocol)."""


class SettingRefusedError(DeviceOpenError):
    """The device refused the settings asked for (a rate its link cannot carry, say).

    ``reason`` is the device's own explanation, without the port and the settings.
    """

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class DeviceIOError(DeviceError):
    """Reading or writing failed while the device was open (unplugged cable, I/O error)."""


class DeviceClosedError(DeviceError):
    """An operation needs an open device."""
