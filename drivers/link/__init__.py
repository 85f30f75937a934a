"""NUCLEO link protocol v1 (see ``docs/protocol.md``): three layers, as pyserial's threaded
``Protocol -> Packetizer`` and x-IMU3's connection -> receiver -> dispatcher.

- :mod:`~drivers.link.protocol`: packet types and their payloads (builders and parsers).
- :mod:`~drivers.link.framing`: CRC-16/CCITT-FALSE, COBS and the 0x00 delimiter.
- :mod:`~drivers.link.decoder`: the streaming decoder (bytes -> packets and RawBlocks) and
  its counters.
- :mod:`~drivers.link.ports`: serial port listing, USB identities and open-error messages.

The transport is :mod:`drivers.serial_link` (pyserial); the far end for tests and demos is
:mod:`drivers.emulated_nucleo`.
"""

from drivers.link.decoder import LinkCounters, LinkDecoder
from drivers.link.framing import encode_packet, frame_bytes, unframe

__all__ = ["LinkCounters", "LinkDecoder", "encode_packet", "frame_bytes", "unframe"]
