"""`sysid decode DEVICE FILE`: decode a raw capture with the drivers' own codecs."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from pathlib import Path

from drivers.airdata.codec import AirDataCodec
from drivers.codec import CodecStats, StreamDecoder
from drivers.surfaces.codec import SurfaceCodec
from drivers.vectornav.codec import AsciiCodec, BinaryCodec, VnAscii, VnPacket

CODECS = {
    "vn200": BinaryCodec,
    "vn200-ascii": AsciiCodec,
    "airdata": AirDataCodec,
    "surfaces": SurfaceCodec,
}
# Captures are read in chunks of this size, as a serial port would deliver them.
CHUNK = 4096


def decode_file(device: str, path: Path) -> tuple[Iterator[object], CodecStats]:
    """Messages of a capture (a generator) and the stats it fills as it goes."""
    decoder = StreamDecoder(CODECS[device]())

    def messages() -> Iterator[object]:
        with Path(path).open("rb") as handle:
            while chunk := handle.read(CHUNK):
                yield from decoder.feed(chunk)

    return messages(), decoder.stats


def as_json(message: object) -> dict:
    """A message as a JSON object: its type and its fields by the codec's names."""
    if isinstance(message, VnPacket):
        return {"type": "vn200", **{k: _plain(v) for k, v in message.fields.items()}}
    if isinstance(message, VnAscii):
        return {"type": message.kind, **message.values}
    fields = dataclasses.asdict(message)
    return {"type": type(message).__name__, **{k: _plain(v) for k, v in fields.items()}}


def _plain(value):
    return list(value) if isinstance(value, tuple) else value


def as_text(message: object) -> str:
    return json.dumps(as_json(message), separators=(", ", "="))[1:-1].replace('"', "")
