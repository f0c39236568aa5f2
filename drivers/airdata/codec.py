"""Aeroprobe µADC ASCII lines (docs/protocols.md, *µADC*): one sample per line,

    NNNNN, XX.XX, +XX.XX, +XX.XX, +XXXX, XXXXXX, XXXXXX, CC\\r\\n

sample number, indicated airspeed m/s, angle of attack deg, sideslip deg, pressure altitude m,
total pressure Pa, static pressure Pa, checksum. Column offsets differ between public parsers,
so lines are parsed by fields (split on commas, stripped). The checksum is two hex digits, the
XOR of every byte of the line before it (separator included) — *unverified* against a unit,
so the rule lives in `checksum` alone.
"""

from __future__ import annotations

from dataclasses import dataclass

from drivers.codec import CodecStats, skip, xor8

MAX_LINE = 96  # a valid line is ~60 bytes
SAMPLE_WRAP = 100_000  # five-digit sample counter
FIELDS = 8


@dataclass(frozen=True)
class AirData:
    """One µADC sample in the device's own units."""

    sample: int
    ias: float
    """Indicated airspeed, m/s."""
    alpha_deg: float
    beta_deg: float
    altitude: float
    """Pressure altitude, m."""
    p_total: float
    """Total pressure, Pa."""
    p_static: float
    """Static pressure, Pa."""


def _candidate_starts(line: bytes) -> list[int]:
    """Offsets where a line may start: five digits then a comma (the sample number)."""
    return [i for i in range(len(line) - 5) if line[i : i + 5].isdigit() and line[i + 5] == 44]


def checksum(before: bytes) -> int:
    """The µADC checksum of the bytes before the checksum field."""
    return xor8(before)


class AirDataCodec:
    """µADC lines; a line that does not parse or check is skipped up to the next line."""

    def __init__(self) -> None:
        self.stats = CodecStats()

    def decode(self, buffer: bytes | bytearray) -> tuple[int, AirData | None]:
        end = buffer.find(b"\n", 0, MAX_LINE)
        if end < 0:
            if len(buffer) < MAX_LINE:
                return 0, None
            # No line end where one must be: garbage up to the next possible line start.
            starts = _candidate_starts(bytes(buffer[1:]))
            drop = 1 + starts[0] if starts else len(buffer) - 6
            return skip(self.stats, drop), None
        line = bytes(buffer[:end]).rstrip(b"\r")
        message = self._parse(line)
        if message is None:
            return skip(self.stats, end + 1), None
        self.stats.frames += 1
        return end + 1, message

    def _parse(self, line: bytes) -> AirData | None:
        """The line, or its tail after garbage that arrived without a line end."""
        first_problem = None
        for start in _candidate_starts(line):
            message, problem = _parse_from(line[start:])
            if message is not None:
                if start:
                    skip(self.stats, start)
                return message
            first_problem = first_problem or problem
        if first_problem == "checksum":
            self.stats.crc_errors += 1
        elif first_problem is not None:
            self.stats.rejected += 1
        return None

    def encode(self, m: AirData) -> bytes:
        before = (
            f"{m.sample % SAMPLE_WRAP:05d}, {m.ias:05.2f}, {m.alpha_deg:+06.2f}, "
            f"{m.beta_deg:+06.2f}, {m.altitude:+05.0f}, {m.p_total:06.0f}, {m.p_static:06.0f}, "
        ).encode()
        return before + f"{checksum(before):02X}".encode() + b"\r\n"


def _parse_from(line: bytes) -> tuple[AirData | None, str | None]:
    """A line starting at its sample number, or None and what was wrong."""
    cut = line.rfind(b",")
    field = line[cut + 1 :]
    digits = cut + 1 + len(field) - len(field.lstrip())  # where the hex digits start
    parts = [p.strip() for p in line[:cut].split(b",")]
    if cut < 0 or len(parts) != FIELDS - 1:
        return None, "fields"
    try:
        check = int(field.strip(), 16)
        sample, values = int(parts[0]), [float(p) for p in parts[1:]]
    except ValueError:
        return None, "fields"
    if checksum(line[:digits]) != check:
        return None, "checksum"
    return AirData(sample, *values), None
