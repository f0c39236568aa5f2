"""`agent.outputs`: the one way a command writes a file.

Bad input tried: an output that is an input under another spelling, through a symbolic link
and through a hard link; two outputs of one command naming one file; a write that fails
halfway (the old file stays whole, no temporary file is left); an output that is a device.
The commands' own tests try the inputs of issue 32 through each command.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

import pytest

from agent.outputs import OutputError, Outputs


def test_an_input_under_any_name_is_refused_naming_both(tmp_path, monkeypatch):
    log = tmp_path / "flight.bin"
    log.write_bytes(b"flight")
    (tmp_path / "hard.bin").hardlink_to(log)
    (tmp_path / "soft.bin").symlink_to(log)
    monkeypatch.chdir(tmp_path)
    outputs = Outputs({log: "the log being imported"})
    for name in (
        "flight.bin",
        "./flight.bin",
        "hard.bin",
        "soft.bin",
        f"../{tmp_path.name}/flight.bin",
    ):
        message = f"--out {Path(name)}: that is {log}, the log being imported"
        with pytest.raises(OutputError, match=re.escape(message)):
            outputs.claim(Path(name))
    assert log.read_bytes() == b"flight"


def test_two_outputs_naming_one_file_are_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    outputs = Outputs({})
    outputs.claim(Path("a.csv"))
    with pytest.raises(OutputError, match=r"--plot a\.csv: the same file as a\.csv"):
        outputs.claim(Path("./a.csv"), "--plot")
    (tmp_path / "b.csv").write_text("")
    (tmp_path / "c.csv").hardlink_to(tmp_path / "b.csv")
    outputs.claim(Path("b.csv"))
    with pytest.raises(OutputError, match=r"the same file as b\.csv, which this command also"):
        outputs.claim(Path("c.csv"))


def test_a_write_that_fails_halfway_leaves_the_old_file_whole(tmp_path):
    out = tmp_path / "models.json"
    out.write_text("old")
    out.chmod(0o640)
    outputs = Outputs({})

    def halfway():
        with outputs.open(out) as handle:
            handle.write(b"new, but only ha")
            raise RuntimeError("a bug halfway")

    with pytest.raises(RuntimeError, match="a bug halfway"):
        halfway()
    assert out.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["models.json"]
    outputs.write_text(out, "new")
    assert out.read_text() == "new"
    assert stat.S_IMODE(out.stat().st_mode) == 0o640  # the file's mode kept
    assert [p.name for p in tmp_path.iterdir()] == ["models.json"]


def test_a_new_file_gets_the_mode_of_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        Outputs({}).write_bytes(tmp_path / "new.csv", b"x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "new.csv").stat().st_mode) == 0o640


def test_a_symbolic_link_is_written_through_and_a_device_directly(tmp_path):
    target = tmp_path / "real.csv"
    target.write_text("old")
    (tmp_path / "link.csv").symlink_to(target)
    outputs = Outputs({})
    outputs.write_text(tmp_path / "link.csv", "new")
    assert (tmp_path / "link.csv").is_symlink()
    assert target.read_text() == "new"
    outputs.write_bytes(Path("/dev/null"), b"nothing")  # no temporary file beside a device
