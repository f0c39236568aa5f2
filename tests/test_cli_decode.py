"""`sysid decode` on the raw captures in tests/data (made by tests/data/generate_captures.py:
50 frames, 23 bytes of garbage after frame 10, one bit flipped in frame 20).

Bad input tried: the garbage and the flipped bit inside each capture, a missing file, an
unknown device name.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agent.cli import main
from agent.config import SurfacePort
from agent.sim import devices
from tests.drivers.rig import state

DATA = Path(__file__).parent / "data"
CAPTURES = {
    "vn200": ("vn200.bin", devices.vn200_binary(state, boot=90.0)),
    "vn200-ascii": ("vn200_ascii.txt", devices.vn200_ascii(state)),
    "airdata": ("airdata.txt", devices.airdata(state)),
    "surfaces": ("surfaces.bin", devices.surfaces(state, SurfacePort(port="x").calibration, 90.0)),
}


@pytest.mark.parametrize("device", list(CAPTURES))
def test_json_is_one_object_of_messages_and_stats(device, capsys):
    name, encode = CAPTURES[device]
    assert main(["decode", device, str(DATA / name), "--json"]) == 0
    document = json.loads(capsys.readouterr().out)  # exactly one object
    messages = document["messages"]
    assert len(messages) == 49
    stats = document["stats"]
    assert stats["frames"] == 49
    assert stats["crc_errors"] + stats["rejected"] == 1
    assert stats["resyncs"] == 2
    frame_20 = encode(100.0 + 20 * 0.01, 20)
    assert stats["bytes_skipped"] == 23 + len(frame_20)  # the garbage and frame 20


def test_json_field_names_follow_the_codec(capsys):
    main(["decode", "vn200", str(DATA / "vn200.bin"), "--json"])
    first = json.loads(capsys.readouterr().out)["messages"][0]
    assert first["type"] == "vn200"
    assert set(first) >= {"common.time_startup", "common.quaternion", "common.angular_rate"}
    assert len(first["common.quaternion"]) == 4
    main(["decode", "airdata", str(DATA / "airdata.txt")])
    assert capsys.readouterr().out.splitlines()[0].startswith("type=AirData, sample=0, ias=")


def test_missing_file_and_unknown_device(tmp_path, capsys):
    assert main(["decode", "airdata", str(tmp_path / "none.txt")]) == 2
    assert "cannot be read" in capsys.readouterr().err
    assert main(["decode", "gps", str(DATA / "airdata.txt")]) == 2
    assert "invalid choice: 'gps'" in capsys.readouterr().err


def test_the_command_lines_device_names_are_the_codecs():
    # The CLI names the devices itself so that `sysid --help` does not import every codec.
    from agent.cli.decode import DEVICES
    from drivers.decode import CODECS

    assert sorted(DEVICES) == sorted(CODECS)
