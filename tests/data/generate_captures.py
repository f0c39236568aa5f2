"""Writes the raw sensor captures in tests/data (deterministic; rerun after a codec change).

    PYTHONPATH=. .venv/bin/python tests/data/generate_captures.py

Each capture is 50 frames from the fake devices (the same encoders the simulator uses) with,
between frames 10 and 11, 23 bytes of garbage and, as frame 20, a frame with one bit flipped:
49 good frames, one checksum error (or a rejected line), and 23 + len(frame 20) bytes skipped.
"""

from __future__ import annotations

import random
from pathlib import Path

from agent.config import SurfacePort
from agent.sim import devices
from tests.drivers.rig import state

HERE = Path(__file__).parent
FRAMES = 50


def capture(encode, flip_at: int) -> bytes:
    rng = random.Random(5)
    out = bytearray()
    for k in range(FRAMES):
        frame = bytearray(encode(100.0 + k * 0.01, k))
        if k == 20:
            frame[flip_at] ^= 0x01
        out += frame
        if k == 10:
            out += bytes(rng.choice(b"garbage!\x00\xff") for _ in range(23))
    return bytes(out)


def main() -> None:
    calibration = SurfacePort(port="x").calibration
    files = {
        "vn200.bin": (devices.vn200_binary(state, boot=90.0), 30),
        "vn200_ascii.txt": (devices.vn200_ascii(state), 12),
        "airdata.txt": (devices.airdata(state), 8),
        "surfaces.bin": (devices.surfaces(state, calibration, boot=90.0), 12),
    }
    for name, (encode, flip_at) in files.items():
        (HERE / name).write_bytes(capture(encode, flip_at))


if __name__ == "__main__":
    main()
