"""MCAP (ROS 2 profile, CDR) for Foxglove and ROS 2: ``sensor_msgs/msg/Imu`` and
``sensor_msgs/msg/MagneticField``, written with the ``mcap`` and ``mcap-ros2-support`` packages.

The messages are fixed-size CDR records (little endian, XCDR1), encoded for a whole block at
once with numpy: ``mcap-ros2-support``'s per-message encoder costs about a millisecond a message
(six minutes for an hour at 104 Hz). Its encoder still encodes the first message of each kind,
and the writer refuses to go on unless the two agree byte for byte.

Every message is stamped (``header.stamp``, and the MCAP log and publish times) with the
recording's ``t`` in integer nanoseconds: the device clock, as the recording has it, not the
wall clock. Covariances as sensor_msgs/Imu's definition says: a matrix of zeros is
"covariance unknown" (this program does not estimate them), and element 0 = -1 says that the
element itself is not given (the orientation, when exported without one).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any, BinaryIO

import numpy as np

IMU_SCHEMA = "sensor_msgs/msg/Imu"
MAG_SCHEMA = "sensor_msgs/msg/MagneticField"
_SEPARATOR = "=" * 80 + "\n"
_COMMON = (
    _SEPARATOR + "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
    + _SEPARATOR + "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    + _SEPARATOR + "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
)
IMU_DEFINITION = (
    "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
    "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
    "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
    "float64[9] linear_acceleration_covariance\n" + _COMMON
    + _SEPARATOR + "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\n"
    "float64 w 1\n"
)
"""sensor_msgs/msg/Imu with its dependencies, in the ROS 2 concatenated form."""
MAG_DEFINITION = (
    "std_msgs/Header header\ngeometry_msgs/Vector3 magnetic_field\n"
    "float64[9] magnetic_field_covariance\n" + _COMMON
)
"""sensor_msgs/msg/MagneticField with its dependencies."""
UNKNOWN_COVARIANCE = [0.0] * 9
"""All zeros: "covariance unknown" (sensor_msgs/Imu)."""
NOT_GIVEN = [-1.0] + [0.0] * 8
"""Element 0 = -1: "no estimate for this data element" (sensor_msgs/Imu)."""
TESLA_PER_MICROTESLA = 1e-6
IMU_DOUBLES = 4 + 9 + 3 + 9 + 3 + 9
"""orientation, its covariance, angular velocity, covariance, acceleration, covariance."""
MAG_DOUBLES = 3 + 9
CDR_LE = b"\x00\x01\x00\x00"
"""The encapsulation header of little-endian plain CDR."""


def _json_safe(value: Any) -> Any:
    """``value`` with every NaN or infinite float replaced by None (JSON has no NaN)."""
    if isinstance(value, dict):
        return {key: _json_safe(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def metadata_strings(values: Mapping[str, Any]) -> dict[str, str]:
    """An MCAP metadata record's map (strings only): text as it is, anything else as JSON
    (a NaN as null)."""
    return {str(k): v if isinstance(v, str) else json.dumps(_json_safe(v), allow_nan=False,
                                                            default=str)
            for k, v in values.items()}


def cdr_records(frame_id: str, t_ns: np.ndarray, doubles: np.ndarray) -> list[bytes]:
    """One CDR message per row: a ``std_msgs/Header`` (stamp from ``t_ns``, ``frame_id``), then
    the row's float64 values (the message's fields after the header, in order)."""
    stamps = np.asarray(t_ns, dtype=np.int64)
    values = np.asarray(doubles, dtype=np.float64)
    text = frame_id.encode("utf-8") + b"\x00"
    string_end = 12 + len(text)  # payload offsets: sec 0, nanosec 4, length 8, bytes 12...
    first = string_end + (-string_end) % 8  # float64 fields are aligned to 8
    size = 4 + first + 8 * values.shape[1]
    table = np.zeros(len(stamps), dtype=np.dtype({
        "names": ["head", "sec", "nanosec", "length", "doubles"],
        "formats": ["V4", "<i4", "<u4", "<u4", (np.dtype("<f8"), values.shape[1])],
        "offsets": [0, 4, 8, 12, 4 + first], "itemsize": size}))
    raw = table.view(np.uint8).reshape(len(stamps), size)
    raw[:, :4] = np.frombuffer(CDR_LE, dtype=np.uint8)
    raw[:, 16:16 + len(text)] = np.frombuffer(text, dtype=np.uint8)
    sec, nanosec = np.divmod(stamps, 1_000_000_000)
    table["sec"], table["nanosec"] = sec, nanosec
    table["length"] = len(text)
    table["doubles"] = values
    data = table.tobytes()
    return [data[k * size:(k + 1) * size] for k in range(len(stamps))]


def imu_doubles(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, quat_wxyz: np.ndarray | None,
                ) -> np.ndarray:
    """(N, 37) the Imu fields after the header; without ``quat_wxyz``: the identity and
    ``orientation_covariance[0] = -1`` (no orientation given)."""
    gyro = np.asarray(gyro_rad_s, dtype=np.float64).reshape(-1, 3)
    n = len(gyro)
    out = np.zeros((n, IMU_DOUBLES))
    if quat_wxyz is None:
        out[:, 3] = 1.0
        out[:, 4] = -1.0
    else:
        q = np.asarray(quat_wxyz, dtype=np.float64).reshape(-1, 4)
        out[:, 0:4] = q[:, [1, 2, 3, 0]]  # ROS orders x, y, z, w
    out[:, 13:16] = gyro
    out[:, 25:28] = np.asarray(accel_m_s2, dtype=np.float64).reshape(-1, 3)
    return out


def _message(kind: str, frame_id: str, stamp: int, row: list[float]) -> dict[str, Any]:
    """The row as mcap-ros2-support's encoder takes it (for the check of the first message)."""
    sec, nanosec = divmod(stamp, 1_000_000_000)
    header = {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}

    def vector(values: list[float]) -> dict[str, float]:
        return dict(zip("xyz", values, strict=True))

    if kind == MAG_SCHEMA:
        return {"header": header, "magnetic_field": vector(row[0:3]),
                "magnetic_field_covariance": row[3:12]}
    return {"header": header, "orientation": dict(zip("xyzw", row[0:4], strict=True)),
            "orientation_covariance": row[4:13], "angular_velocity": vector(row[13:16]),
            "angular_velocity_covariance": row[16:25], "linear_acceleration": vector(row[25:28]),
            "linear_acceleration_covariance": row[28:37]}


class McapImuWriter:
    """Writes IMU (and magnetometer) messages into an open binary file.

    ``frame_id`` is every header's frame; ``orientation`` False writes the identity with
    ``orientation_covariance[0] = -1`` (no orientation given).
    """

    def __init__(self, handle: BinaryIO, *, frame_id: str, imu_topic: str, mag_topic: str,
                 orientation: bool = True) -> None:
        from mcap.well_known import MessageEncoding, SchemaEncoding
        from mcap.writer import CompressionType, Writer
        from mcap_ros2 import __version__ as ros2_version

        self._writer = Writer(handle, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2",
                           library=f"inclinometer; mcap-ros2-support {ros2_version}")
        self._channels: dict[str, int] = {}
        for kind, topic, definition in ((IMU_SCHEMA, imu_topic, IMU_DEFINITION),
                                        (MAG_SCHEMA, mag_topic, MAG_DEFINITION)):
            schema = self._writer.register_schema(kind, SchemaEncoding.ROS2,
                                                  definition.encode("utf-8"))
            self._channels[kind] = self._writer.register_channel(topic, MessageEncoding.CDR,
                                                                 schema)
        self._checked: set[str] = set()
        self.frame_id = frame_id
        self.imu_topic = imu_topic
        self.mag_topic = mag_topic
        self.orientation = orientation
        self.imu_messages = 0
        self.mag_messages = 0

    def add_metadata(self, name: str, values: Mapping[str, Any]) -> None:
        self._writer.add_metadata(name, metadata_strings(values))

    def _check(self, kind: str, stamp: int, row: np.ndarray, data: bytes) -> None:
        """The first message of a kind must be what mcap-ros2-support encodes (else a bug)."""
        from mcap_ros2._dynamic import serialize_dynamic

        definition = MAG_DEFINITION if kind == MAG_SCHEMA else IMU_DEFINITION
        encode = serialize_dynamic(kind, definition)[kind]
        expected = encode(_message(kind, self.frame_id, stamp, row.tolist()))
        if bytes(expected) != data:
            raise RuntimeError(f"{kind}: this encoder and mcap-ros2-support's disagree")
        self._checked.add(kind)

    def _write(self, kind: str, t_ns: np.ndarray, doubles: np.ndarray, sequence: int) -> int:
        stamps = np.asarray(t_ns, dtype=np.int64)
        if len(stamps) == 0:
            return 0
        records = cdr_records(self.frame_id, stamps, doubles)
        if kind not in self._checked:
            self._check(kind, int(stamps[0]), doubles[0], records[0])
        channel = self._channels[kind]
        add = self._writer.add_message
        for k, (stamp, data) in enumerate(zip(stamps.tolist(), records, strict=True)):
            add(channel_id=channel, log_time=stamp, data=data, publish_time=stamp,
                sequence=sequence + k)
        return len(records)

    def write_imu(self, t_ns: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray,
                  quat_wxyz: np.ndarray | None) -> None:
        """One Imu message per row (vectors and quaternions already in the export's frame)."""
        doubles = imu_doubles(gyro_rad_s, accel_m_s2, quat_wxyz if self.orientation else None)
        self.imu_messages += self._write(IMU_SCHEMA, t_ns, doubles, self.imu_messages)

    def write_mag(self, t_ns: np.ndarray, field_ut: np.ndarray) -> None:
        """One MagneticField message per row with a field (rows of NaN are skipped); in tesla."""
        field = np.asarray(field_ut, dtype=np.float64).reshape(-1, 3)
        fresh = np.all(np.isfinite(field), axis=1)
        doubles = np.zeros((int(fresh.sum()), MAG_DOUBLES))
        doubles[:, 0:3] = field[fresh] * TESLA_PER_MICROTESLA
        self.mag_messages += self._write(MAG_SCHEMA, np.asarray(t_ns)[fresh], doubles,
                                         self.mag_messages)

    def finish(self) -> None:
        """Write the summary and footer (the file is incomplete without it)."""
        self._writer.finish()
