"""Devices are found by URL scheme and imported only when chosen (as python-can's interfaces).

Built-in schemes are listed in ``_BUILTIN``; other packages add drivers through the
``inclinometer.drivers`` entry-point group (name = scheme, value = ``module:Class``).
"""

from __future__ import annotations

import functools
import importlib
import re
from importlib.metadata import entry_points
from urllib.parse import urlsplit

from drivers.base import Device, DeviceDescriptor
from drivers.errors import DeviceOpenError, DeviceUrlError
from drivers.url_options import Option

DEFAULT_DEVICE_URL = "sim://interactive"

_BUILTIN: dict[str, tuple[str, str]] = {
    "sim": ("drivers.sim.device", "SimulatedDevice"),
    "text": ("drivers.text_lines", "TextLineDevice"),
    "lsm6dsox": ("drivers.lsm6dsox_direct.device", "Lsm6dsoxDirectDevice"),  # host names the bus
    "serial": ("drivers.serial_link", "SerialLinkDevice"),
    "port": ("drivers.serial_link", "PortDevice"),  # a bare port name: v1 or text, detected
    "replay": ("drivers.replay", "ReplayDevice"),  # also a bare path to a .csv or .csv.gz
}
_BARE_PORT = re.compile(r"(/|\\\\\.\\|\./)\S+|(?i:com)\d+")
"""A serial port given without a scheme: ``/dev/ttyACM0``, ``COM3``, ``\\\\.\\COM12``."""


def _schemes() -> dict[str, tuple[str, str]]:
    schemes = dict(_BUILTIN)
    for name, target in _plugin_schemes():
        schemes.setdefault(name, target)
    return schemes


@functools.cache
def _plugin_schemes() -> tuple[tuple[str, tuple[str, str]], ...]:
    """Drivers other packages declare (read once: scanning the installed packages' metadata
    took most of a device listing)."""
    found = []
    for ep in entry_points(group="inclinometer.drivers"):
        module, _, cls = ep.value.partition(":")
        found.append((ep.name, (module, cls)))
    return tuple(found)


def scheme_of(url: str) -> str:
    """The scheme of a device URL (``sim`` for ``sim://static``)."""
    if "://" not in url and url.strip().lower().endswith((".csv", ".csv.gz")):
        return "replay"  # a recording file
    if "://" not in url and _BARE_PORT.fullmatch(url.partition("?")[0]):
        return "port"
    parts = urlsplit(url)
    if not parts.scheme or "://" not in url:
        raise DeviceUrlError(
            f"{url!r} is not a device URL; expected something like {DEFAULT_DEVICE_URL!r} "
            "or a serial port such as /dev/ttyACM0 or COM3"
        )
    return parts.scheme.lower()


def driver_class(scheme: str) -> type[Device]:
    """Import and return the driver class for ``scheme``."""
    schemes = _schemes()
    if scheme not in schemes:
        known = ", ".join(sorted(f"{s}://" for s in schemes))
        raise DeviceUrlError(f"no driver for {scheme}:// (known: {known})")
    module_name, class_name = schemes[scheme]
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise DeviceOpenError(
            f"the {scheme}:// driver needs a package that is not installed: {exc.name or exc}"
        ) from exc
    return getattr(module, class_name)


def driver_for(url: str) -> type[Device]:
    """The driver class for ``url``: ask it what its devices declare (``replayable``,
    ``knows_truth``, ``steerable``, ``unpaced_url``) without opening one."""
    return driver_class(scheme_of(url))


def create_device(url: str) -> Device:
    """A closed device object for ``url`` (raises :class:`DeviceUrlError` for a bad URL)."""
    return driver_class(scheme_of(url))(url)


def open_device(url: str) -> Device:
    """Create and open the device named by ``url``."""
    device = create_device(url)
    device.open()
    return device


def available_devices() -> list[DeviceDescriptor]:
    """Everything that could be connected now, from every driver that imports."""
    found: list[DeviceDescriptor] = []
    for scheme in _schemes():
        try:
            cls = driver_class(scheme)
        except DeviceOpenError:
            continue
        found.extend(cls.discover())
    return found


def driver_options(name: str) -> tuple[Option, ...]:
    """The URL options a driver declares: of a scheme (``sim``, ``serial``) or of a URL
    (``sim://static``: the general options and that scenario's).

    Raises :class:`DeviceUrlError` for an unknown scheme, :class:`DeviceOpenError` when the
    driver cannot be imported.
    """
    text = name.strip()
    if "://" in text or any(c in text for c in "/\\.?"):
        return driver_class(scheme_of(text)).options_for(text)
    return driver_class(text.lower().removesuffix(":")).options_for("")
