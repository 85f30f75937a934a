"""Typed device errors. Each message is written for the user who will read it in the GUI."""


class DeviceError(Exception):
    """Base class of every error a driver raises."""


class DeviceUrlError(DeviceError):
    """The device URL is malformed, or names an unknown scheme or option."""


class DeviceOpenError(DeviceError):
    """The device could not be opened (missing, busy, permission denied, wrong protocol)."""


class DeviceIOError(DeviceError):
    """Reading or writing failed while the device was open (unplugged cable, I/O error)."""


class DeviceClosedError(DeviceError):
    """An operation needs an open device."""
