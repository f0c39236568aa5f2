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
from tests.capped import sysid
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


def test_json_streams_a_large_capture_in_little_memory(tmp_path):
    """Bad input tried: `decode airdata BIG --json` on a valid 6 MB capture (the test capture
    2100 times over: 102 900 messages). Every message used to be held, then the whole
    document as one string (about 20 times the capture; 1.1 GB for 60 MB). Streamed, it runs
    under a limit of 80 MB of address space, and stdout is still one JSON object."""
    capture = tmp_path / "big.txt"
    capture.write_bytes((DATA / "airdata.txt").read_bytes() * 2100)
    with (tmp_path / "out.json").open("w") as out:
        done = sysid(
            "decode", "airdata", str(capture), "--json", cwd=tmp_path, limit=80 << 20, stdout=out
        )
    assert done.returncode == 0, done.stderr
    document = json.loads((tmp_path / "out.json").read_text())
    assert len(document["messages"]) == 49 * 2100
    assert document["messages"][-1]["type"] == "AirData"
    assert document["stats"]["frames"] == 49 * 2100


def test_an_error_while_streaming_still_closes_the_one_json_object(monkeypatch, capsys):
    """Bad input tried: a capture whose reading fails after three messages (an I/O error on a
    failing card): stdout is still exactly one JSON object, the three messages and the error
    in it, and the traceback on stderr."""
    import drivers.decode

    real = drivers.decode.decode_file

    def failing(device, path):
        messages, stats = real(device, path)

        def three_then_fail():
            for k, message in enumerate(messages):
                if k == 3:
                    raise OSError(5, "Input/output error")
                yield message

        return three_then_fail(), stats

    monkeypatch.setattr(drivers.decode, "decode_file", failing)
    assert main(["decode", "airdata", str(DATA / "airdata.txt"), "--json"]) == 1
    out, err = capsys.readouterr()
    document = json.loads(out)  # exactly one object
    assert len(document["messages"]) == 3
    assert document["error"]["message"] == "after 3 item(s): OSError: [Errno 5] Input/output error"
    assert document["error"]["exit"] == 1
    assert "Traceback" in err
