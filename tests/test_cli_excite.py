"""`sysid excite`: CSV, JSON and plot previews, and bad input.

Bad input tried: a plan file that is not JSON, a plan with an unknown control, a missing plan
file, an amplitude beyond the envelope, a malformed --amplitude, an amplitude of 0, nan or
inf, a rate of 0, a harmonic of 10**400, and a plot path in a directory that does not exist.
Each gives a message and exit 2.
"""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from agent.cli import main
from agent.excitation.plan import preset
from tests.capped import sysid


def test_csv_has_a_header_and_one_row_per_command(capsys):
    assert main(["excite", "--preset", "full", "--rate", "50", "--csv"]) == 0
    text = capsys.readouterr().out
    header, *_ = text.splitlines()
    assert header == "time,aileron,elevator,rudder,throttle"
    data = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1)
    assert np.allclose(np.diff(data[:, 0]), 0.02)
    assert data.shape[0] == round(81.0 * 50) + 1  # 1 s lead, one 80 s multisine period
    assert np.max(np.abs(data[:, 1])) == pytest.approx(4.0, abs=1e-5)  # aileron, degrees
    assert np.max(np.abs(data[:, 4])) == pytest.approx(10.0, abs=1e-5)  # throttle, percent
    assert data[-1, 1:] == pytest.approx(0.0, abs=1e-9)  # whole periods end at trim


def test_csv_columns_follow_the_configured_channel_names(tmp_path, capsys):
    config = tmp_path / "config.toml"
    config.write_text('[identification.channels]\naileron = "dA"\nrudder = "dR"\n')
    assert main(["excite", "--preset", "lateral", "--config", str(config)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == "time,dA,dR"


def test_json_summary(capsys):
    assert main(["excite", "--preset", "full", "--json", "--amplitude", "rudder=2"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["duration_s"] == pytest.approx(81.02)
    assert report["controls"]["rudder"]["peak"] == pytest.approx(2.0)
    # 25 harmonics per surface: clipping alone left 1.25; the p-norm polish reaches ≤ 1.12.
    assert all(report["controls"][c]["rpf"] <= 1.12 for c in ("aileron", "rudder", "elevator"))
    assert report["max_cross_correlation"] < 1e-9
    assert report["warnings"] == []


def test_servo_warnings_reach_the_json_and_stderr(tmp_path, capsys):
    config = tmp_path / "config.toml"
    # Listing controls replaces the default table: the elevator's servo is slow (20 °/s).
    config.write_text(
        "[excitation.surfaces.elevator]\nchannel = 2\nus_per_unit = 20\n"
        "max_amplitude = 10\nrate_limit = 20\ntravel = 25\n"
        '[excitation.surfaces.throttle]\nchannel = 3\nunit = "percent"\nus_per_unit = 10\n'
        "max_amplitude = 30\nrate_limit = 400\ntravel = 50\n"
    )
    assert main(["excite", "--preset", "longitudinal", "--json", "--config", str(config)]) == 0
    captured = capsys.readouterr()
    assert "elevator: needs" in json.loads(captured.out)["warnings"][0]
    assert "warning: elevator: needs" in captured.err


def test_plot_and_plan_file(tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_bytes(preset("longitudinal").to_bytes())
    png = tmp_path / "plan.png"
    assert main(["excite", "--plan", str(plan), "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--plan", "{bad}"], "not a valid plan"),
        (["--plan", "{unknown}"], "unknown control"),
        (["--plan", "{missing}"], "cannot be read"),
        (["--preset", "lateral", "--amplitude", "aileron=15"], "exceeds its max_amplitude"),
        (["--preset", "lateral", "--amplitude", "aileron:3"], "CONTROL=VALUE"),
        # A pydantic dump with a URL before; now what to give.
        (["--preset", "lateral", "--amplitude", "aileron=0"], "aileron=0: give a finite ampl"),
        (["--preset", "lateral", "--amplitude", "aileron=nan"], "nan: give a finite amplitude"),
        (["--preset", "full", "--amplitude", "throttle=inf"], "inf: give a finite amplitude"),
        (["--preset", "lateral", "--rate", "0"], "--rate must be"),
        (["--preset", "lateral", "--plot", "{nodir}"], "cannot be written"),
    ],
)
def test_bad_input_is_a_clear_error(tmp_path, capsys, args, message):
    (tmp_path / "bad.json").write_text("{not json")
    (tmp_path / "unknown.json").write_text(
        '{"id":"x","axes":"lateral","segments":[{"signals":{"flaps":'
        '{"kind":"doublet","pulse_s":1,"amplitude":2}}}]}'
    )
    paths = {
        "{bad}": tmp_path / "bad.json",
        "{unknown}": tmp_path / "unknown.json",
        "{missing}": tmp_path / "missing.json",
        "{nodir}": tmp_path / "no" / "such" / "dir.png",
    }
    args = [str(paths.get(a, a)) for a in args]
    assert main(["excite", *args]) == 2
    err = capsys.readouterr().err
    assert "sysid excite: error:" in err
    assert message in err
    assert "pydantic" not in err


def test_a_harmonic_of_10_to_the_400_is_refused_with_its_key(tmp_path, capsys):
    """Bad input tried: a plan file whose multisine harmonic is 10**400 (an OverflowError
    traceback). Refused naming the harmonic's key, without pydantic's echoes of it."""
    plan = tmp_path / "plan.json"
    plan.write_text(
        '{"id":"x","axes":"lateral","segments":[{"signals":{"aileron":{"kind":"multisine",'
        f'"harmonics":[{10**400}],"period_s":10,"amplitude":3}}}}}}]}}'
    )
    assert main(["excite", "--plan", str(plan), "--json"]) == 2
    out, err = capsys.readouterr()
    assert json.loads(out)["error"]["exit"] == 2
    assert "segments.0.signals.aileron.multisine.harmonics.0: Input should be less than" in err
    assert "Tuple should have" not in err
    assert "Traceback" not in err


def test_an_internal_error_still_leaves_one_json_object(monkeypatch, capsys):
    # Bad input tried: none the code foresaw. A bug inside a command (here the plan's summary
    # raising) must not leave `--json` with a traceback and an empty stdout.
    import agent.excitation.plan

    def broken(*args, **kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr(agent.excitation.plan, "summary", broken)
    assert main(["excite", "--preset", "lateral", "--json"]) == 1
    out, err = capsys.readouterr()
    assert json.loads(out) == {
        "error": {"kind": "internal", "exit": 1, "message": "internal error: RuntimeError: a bug"}
    }
    assert "Traceback" in err
    with pytest.raises(RuntimeError):  # without --json the traceback is the report
        main(["excite", "--preset", "lateral"])


def test_a_plot_format_matplotlib_does_not_know_is_a_clear_error(tmp_path, capsys):
    """Bad input tried: --plot x.xyz (matplotlib's ValueError used to be a traceback)."""
    assert main(["excite", "--preset", "lateral", "--plot", str(tmp_path / "x.xyz")]) == 2
    err = capsys.readouterr().err
    assert "Format 'xyz' is not supported" in err
    assert "Traceback" not in err


def test_an_amplitude_for_a_control_the_preset_does_not_play_is_refused(capsys):
    """Bad input tried: --amplitude ailron=6 (a typo: the plan used to fly at the default
    amplitude) and elevator=3 on the lateral preset."""
    for item in ("ailron=6", "elevator=3"):
        assert main(["excite", "--preset", "lateral", "--amplitude", item]) == 2
        err = capsys.readouterr().err
        assert "the lateral preset plays aileron, rudder; no amplitude for" in err, err


@pytest.mark.parametrize("spelling", ["same", "hard link"])
def test_a_plot_onto_the_plan_is_refused_and_the_plan_kept(tmp_path, capsys, spelling):
    """Bad input tried: `excite --plan p.png --plot p.png` (the plan used to be read and then
    overwritten by the picture), and --plot naming a hard link to the plan: exit 2 naming
    both, the plan's bytes unchanged, nothing else written."""
    plan = tmp_path / "p.png"
    plan.write_bytes(preset("longitudinal").to_bytes())
    before = plan.read_bytes()
    plot = plan
    if spelling == "hard link":
        plot = tmp_path / "picture.png"
        plot.hardlink_to(plan)
    assert main(["excite", "--plan", str(plan), "--plot", str(plot)]) == 2
    err = capsys.readouterr().err
    assert f"--plot {plot}: that is {plan}, the plan" in err, err
    assert plan.read_bytes() == before
    assert len(list(tmp_path.iterdir())) == (1 if spelling == "same" else 2)


def test_a_plot_that_fails_halfway_leaves_the_old_picture(small_disk, capsys):
    """Bad input tried: --plot onto a disk that fills up while the picture is written (a real
    256 KiB tmpfs): the picture from before is still there, whole, and no temporary file is
    left (matplotlib used to truncate it first and stop halfway)."""
    picture = small_disk / "plan.png"
    assert main(["excite", "--preset", "lateral", "--plot", str(picture)]) == 0
    before = picture.read_bytes()
    # The four-control preset's picture is larger than the whole disk.
    assert main(["excite", "--preset", "full", "--plot", str(picture)]) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert picture.read_bytes() == before
    assert [p.name for p in small_disk.iterdir()] == ["plan.png"]


def test_a_plan_file_without_end_is_refused_at_its_bound(tmp_path):
    """Bad input tried: --plan /dev/zero (read whole before: it grew until the memory ran
    out), in a process of its own with a memory limit."""
    done = sysid("excite", "--plan", "/dev/zero", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "/dev/zero: longer than 1048576 bytes; not a plan" in done.stderr
