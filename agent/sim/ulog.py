"""PX4 ULog (.ulg) files, written from the format specification (PX4 docs, "ULog File Format"),
for the importer's tests and for simulated flights: a 16-byte header (`ULog` 01 12 35, version
1, start time µs), the flag bits message, one format message per topic, info messages, then
`A` (subscribe a topic under a message id) and `D` (one sample) messages. Every message is
`uint16 size, uint8 type, payload`, little-endian, fields packed without padding.
"""

from __future__ import annotations

import struct
from pathlib import Path

from agent.sim.logfile import LogFile

MAGIC = b"ULog\x01\x12\x35"
TYPES = {
    "uint64_t": "Q",
    "int64_t": "q",
    "uint32_t": "I",
    "int32_t": "i",
    "uint16_t": "H",
    "int16_t": "h",
    "uint8_t": "B",
    "int8_t": "b",
    "float": "f",
    "double": "d",
    "bool": "?",
    "char": "c",
}
# The PX4 topics the importer maps (the fields it reads, timestamp first, as PX4 defines them).
TOPICS = {
    "vehicle_attitude": "uint64_t timestamp;uint64_t timestamp_sample;float[4] q",
    "vehicle_angular_velocity": "uint64_t timestamp;uint64_t timestamp_sample;float[3] xyz",
    "vehicle_acceleration": "uint64_t timestamp;uint64_t timestamp_sample;float[3] xyz",
    "airspeed_validated": "uint64_t timestamp;float indicated_airspeed_m_s;"
    "float calibrated_airspeed_m_s;float true_airspeed_m_s",
    "vehicle_local_position": "uint64_t timestamp;uint64_t timestamp_sample;bool xy_valid;"
    "bool z_valid;bool v_xy_valid;bool v_z_valid;float x;float y;float z;float vx;float vy;"
    "float vz;float heading",
    "airflow_aoa": "uint64_t timestamp;float aoa_rad;bool valid",
    "airflow_slip": "uint64_t timestamp;float slip_rad;bool valid",
    "actuator_outputs": "uint64_t timestamp;uint32_t noutputs;float[16] output",
}


def _struct(fields: str) -> tuple[str, list[tuple[str, int]]]:
    """struct format and (name, count) of each field of a ULog format string."""
    fmt, names = "<", []
    for field in fields.split(";"):
        kind, name = field.split(" ")
        count = 1
        if "[" in kind:
            kind, count = kind[: kind.index("[")], int(kind[kind.index("[") + 1 : -1])
        fmt += f"{count}{TYPES[kind]}" if count > 1 else TYPES[kind]
        names.append((name, count))
    return fmt, names


class ULogWriter(LogFile):
    """`write(topic, timestamp=µs, q=[w, x, y, z], …)`; fields not given are zero."""

    def __init__(self, path: str | Path, start_us: int = 0, sys_name: str = "PX4"):
        super().__init__(path)
        self._file.write(MAGIC + bytes([1]) + struct.pack("<Q", start_us))
        self._message("B", bytes(8) + bytes(8) + struct.pack("<3Q", 0, 0, 0))
        self._structs = {}
        for topic, fields in TOPICS.items():
            self._message("F", f"{topic}:{fields}".encode())
            self._structs[topic] = _struct(fields)
        key = b"char[%d] sys_name" % len(sys_name)
        self._message("I", bytes([len(key)]) + key + sys_name.encode())
        self._ids: dict[str, int] = {}

    def _message(self, kind: str, payload: bytes) -> None:
        self._file.write(struct.pack("<HB", len(payload), ord(kind)) + payload)

    def write(self, topic: str, **values) -> None:
        if topic not in self._ids:
            self._ids[topic] = len(self._ids)
            self._message("A", struct.pack("<BH", 0, self._ids[topic]) + topic.encode())
        fmt, names = self._structs[topic]
        flat = []
        for name, count in names:
            if count > 1:
                given = list(values.get(name, []))
                flat += given[:count] + [0] * (count - len(given))
            else:
                flat.append(values.get(name, 0))
        self._message("D", struct.pack("<H", self._ids[topic]) + struct.pack(fmt, *flat))
