"""Config: defaults, the bundled file, and bad files reported by key path with exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from agent.cli import main
from agent.config import Config, ConfigError, load_config

ROOT = Path(__file__).resolve().parents[1]


def test_bundled_config_is_valid_and_equals_the_defaults():
    assert load_config(ROOT / "config.toml") == Config()


def test_sections_are_frozen_and_documented():
    config = Config()
    with pytest.raises(ValidationError):
        config.identification.markov = 3
    for name, field in type(config.identification).model_fields.items():
        assert field.description, f"identification.{name} has no docstring"
    for name, field in type(config.identification.channels).model_fields.items():
        assert field.description, f"channels.{name} has no docstring"
    for section in (
        config.excitation,
        config.excitation.envelope,
        config.excitation.surfaces["rudder"],
    ):
        for name, field in type(section).model_fields.items():
            assert field.description, f"{type(section).__name__}.{name} has no docstring"


def test_axis_sets_use_configured_channel_names(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[identification.channels]\nbeta = "sideslip"\nairspeed = "tas"\n')
    channels = load_config(path).identification.channels
    assert channels.axis_set("lateral") == (("aileron", "rudder"), ("sideslip", "p", "r", "phi"))
    assert channels.axis_set("full")[1][0] == "tas"
    assert channels.role_of("sideslip") == "beta"


AIL = (
    "[excitation.surfaces.aileron]\nchannel = 1\nus_per_unit = 20\nmax_amplitude = 10\n"
    "rate_limit = 200\ntravel = 25\n"
)


@pytest.mark.parametrize(
    ("text", "key", "reason"),
    [
        ("[identification]\nmarkov = 0\n", "identification.markov", "integer ≥ 1"),
        ("[identification]\nmarkov = 'many'\n", "identification.markov", '"auto"'),
        ("[identification]\norder_max = 'x'\n", "identification.order_max", "valid integer"),
        ("[identification]\ntrim_seconds = -1\n", "identification.trim_seconds", "greater"),
        ("[identification]\nmarkv = 3\n", "identification.markv", "Extra inputs"),
        ("[identification]\naxes = 'yaw'\n", "identification.axes", "lateral"),
        ('[identification.channels]\np = "r"\n', "identification.channels", "repeated: r"),
        ("[identification]\ndecimation = 0\n", "identification.decimation", "integer ≥ 1"),
        # `config check` accepted it; identify then built a 1.6 GB filter.
        ("[identification]\ndecimation = 10000000\n", "identification.decimation", "1 to 1000"),
        (
            "[identification]\nband_hz = -1\n",
            "identification.band_hz",
            "greater than or equal to 0.01",
        ),
        ("[identification]\nrefine = 'maybe'\n", "identification.refine", "valid boolean"),
        ("[identification]\nmethod = 'fourier'\n", "identification.method", "'time'"),
        ("[identification]\nnoise_model = 'kalman'\n", "identification.noise_model", "'auto'"),
        ("[identification]\nperiod_s = 0\n", "identification.period_s", "greater than 0"),
        ("[identification]\nsmoothing_s = -0.1\n", "identification.smoothing_s", "greater than 0"),
        ("[identification\n", "(syntax)", "line 1"),
        ("[excitation]\nrate_hz = 20\n", "excitation.rate_hz", "greater than or equal to 50"),
        ("[excitation]\nswitch_channel = 1\n", "excitation", "never overridden"),
        (f"{AIL}{AIL.replace('aileron', 'flaps')}", "excitation", "unknown control flaps"),
        (f"{AIL}{AIL.replace('aileron', 'rudder')}", "excitation", "its own RC channel"),
        (
            AIL.replace("channel = 1", "channel = 1\nmin_us = 2000"),
            "excitation.surfaces.aileron",
            "must be below max_us",
        ),
        (
            AIL.replace("us_per_unit = 20", "us_per_unit = 0"),
            "excitation.surfaces.aileron.us_per_unit",
            "greater than 0",
        ),
        (AIL.replace("\nchannel = 1", ""), "excitation.surfaces.aileron.channel", "Field required"),
        (
            AIL.replace("channel = 1", "channel = 1\ndirection = 2"),
            "excitation.surfaces.aileron.direction",
            "1 or -1",
        ),
        ("[excitation.envelope]\nmin_airspeed = 40\n", "excitation.envelope", "below max_airspeed"),
        ('[sensors.vn200]\nfields = ["common.nope"]\n', "sensors.vn200", "unknown VN-200"),
        ("[sensors.airdata]\nbaud = 10\n", "sensors.airdata.baud", "greater than or equal"),
        (
            "[sensors.surfaces.calibration.rudder]\npoly = [0, 1]\n",
            "sensors.surfaces",
            "missing ['aileron_left'",
        ),
        (
            "[sensors.surfaces.calibration.x]\ntable = [[0, 0], [0, 1]]\n",
            "sensors.surfaces.calibration.x",
            "strictly increasing",
        ),
        ('[recorder]\nchannels = ["p", "warp"]\n', "recorder", "unknown channels ['warp']"),
        ("[recorder]\nrate_hz = 0\n", "recorder.rate_hz", "greater than or equal to 1"),
        ('[link]\npeer = "0013A2004"\n', "link.peer", "16 hex digits"),
        ('[link]\npeer = "0013A20040A1B2CZ"\n', "link.peer", "16 hex digits"),
        # Absurd and non-finite values (identify used to hang on band_hz = 1e-9).
        ("[identification]\nband_hz = 1e-9\n", "identification.band_hz", "greater than or"),
        (
            "[excitation.envelope]\nmax_airspeed = inf\n",
            "excitation.envelope.max_airspeed",
            "finite number",
        ),
        (
            "[excitation.envelope]\nmax_duration_s = nan\n",
            "excitation.envelope.max_duration_s",
            "finite number",
        ),
        # A decimation the aircraft method used to ignore without a word.
        (
            '[identification]\nmethod = "aircraft"\ndecimation = 4\n',
            "identification",
            'takes no decimation (given 4): set decimation = "auto", or method = "time"',
        ),
    ],
)
def test_bad_config_names_key_and_reason(tmp_path, capsys, text, key, reason):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert any(k == key and reason in why for k, why in caught.value.problems)
    assert main(["config", "check", str(path)]) == 2
    err = capsys.readouterr().err
    assert key in err
    assert reason in err
    assert "Traceback" not in err


def test_an_unset_direction_is_arduplanes_sense_for_the_role(tmp_path):
    # ArduPlane's RC inputs rise for roll right and more throttle: −1 for the aileron (eq. 3.1's
    # δA > 0 rolls left), +1 for the throttle; a direction given is kept.
    throttle = AIL.replace("aileron", "throttle").replace("channel = 1", "channel = 3")
    rudder = AIL.replace("aileron", "rudder").replace("channel = 1", "channel = 4\ndirection = 1")
    path = tmp_path / "directions.toml"
    path.write_text(AIL + throttle + rudder)
    surfaces = load_config(path).excitation.surfaces
    assert surfaces["aileron"].direction == -1
    assert surfaces["throttle"].direction == 1
    assert surfaces["rudder"].direction == 1


def test_config_check_ok_and_missing_file(tmp_path, capsys):
    assert main(["config", "check", str(ROOT / "config.toml")]) == 0
    assert "ok" in capsys.readouterr().out
    assert main(["config", "check", str(tmp_path / "nope.toml")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_link_key_file_problems_are_explained(tmp_path):
    from agent.config import load_key

    # Bad input tried: a missing key file, a key that is not hex, a key that is too short.
    with pytest.raises(ValueError, match=r"make one with: sysid keygen .*none\.key"):
        load_key(tmp_path / "none.key")
    (tmp_path / "bad.key").write_text("zz" * 32)
    with pytest.raises(ValueError, match="must be hex digits"):
        load_key(tmp_path / "bad.key")
    (tmp_path / "short.key").write_text("ab" * 8 + "\n")
    with pytest.raises(ValueError, match="has 8 bytes; use 32"):
        load_key(tmp_path / "short.key")
    good = bytes.fromhex("5f1e9c27d4a0b38e61c7f2094ad35be8c06f1a729e4d83b5f02c6e917ad4b358")
    (tmp_path / "good.key").write_text(good.hex() + "\n")
    (tmp_path / "good.key").chmod(0o600)
    assert load_key(tmp_path / "good.key") == good
    # Bad input tried: a key of one repeated byte, and a good key readable by other users.
    (tmp_path / "weak.key").write_text("ab" * 32 + "\n")
    (tmp_path / "weak.key").chmod(0o600)
    with pytest.raises(ValueError, match="only 1 distinct byte values in 32: not a random key"):
        load_key(tmp_path / "weak.key")
    # Bad input tried: keys that pass a count of distinct bytes but were never random.
    weak = {
        "sequence": (bytes(range(32)).hex(), "steps between its bytes take only 1 values"),
        "password": (b"hunter2-hunter2-hunter2-hunter2!".hex(), "printable text in hex"),
        "passphrase": ("correct horse battery staple", "must be hex digits"),
        "block": ("5f1e9c27d4a0b38e61c7f2094ad35be8" * 2, "repeats every 16 bytes"),
    }
    for name, (text, reason) in weak.items():
        (tmp_path / f"{name}.key").write_text(text + "\n")
        (tmp_path / f"{name}.key").chmod(0o600)
        with pytest.raises(ValueError, match=reason) as refused:
            load_key(tmp_path / f"{name}.key")
        assert "sysid keygen" in str(refused.value)  # and how to make a good one
    (tmp_path / "good.key").chmod(0o644)
    with pytest.raises(ValueError, match=r"readable by other users \(mode 644\); chmod 600"):
        load_key(tmp_path / "good.key")


def test_the_simulators_agent_config_file_loads_back_to_the_same_config(tmp_path):
    # `simulated(agent_process=True)` writes only what differs from the defaults: the sensor
    # ports, the autopilot URL, the link files, the log directory, and the real-time priority
    # the benchmarks fly with.
    from agent.config import to_toml
    from agent.sim.flight import agent_config

    for priority, speed in ((None, 60.0), (10, 90.0)):
        config = agent_config(
            tmp_path, tmp_path / "ports", ("127.0.0.1", 14555), "lateral", priority, speed
        )
        path = tmp_path / "agent.toml"
        path.write_text(to_toml(config))
        assert load_config(path) == config
        assert load_config(path).runtime.realtime_priority == priority
        # The envelope fits the simulated aircraft: a 90 kt PA-28's trim (46.3 m/s) is inside
        # it, where the default (35 m/s at most) refused every plan.
        envelope = config.excitation.envelope
        assert envelope.min_airspeed < speed * 0.514444 < envelope.max_airspeed
    # Taken about the trim's true airspeed when the plant gives it (what the air data measure).
    config = agent_config(
        tmp_path, tmp_path / "ports", ("127.0.0.1", 14555), "full", None, 50.0, true_airspeed=27.0
    )
    envelope = config.excitation.envelope
    assert (envelope.min_airspeed, envelope.max_airspeed) == pytest.approx((0.6 * 27.0, 1.3 * 27.0))


@pytest.mark.parametrize("period", [float("inf"), float("nan"), 1e-9, 1e6])
def test_an_update_period_from_the_radio_is_range_checked(period):
    """Bad input tried (identification settings from the ground): an infinite period (it
    stopped the periodic loop), NaN, 1e-9 s (it spun it) and 1e6 s."""
    from agent.link import messages

    with pytest.raises(ValidationError):
        messages.IdentSettings(axes="lateral", update_period_s=period)
    assert messages.IdentSettings(axes="lateral", update_period_s=20.0).update_period_s == 20.0


def test_a_config_written_as_toml_reads_back_equal(tmp_path):
    """`to_toml` writes what differs from the defaults (the simulator's agent config file);
    `load_config` reads it back to an equal config: ports, the peer's address, a table of
    calibration points, a nested envelope, a None left out."""
    from agent.config import (
        Calibration,
        Config,
        Envelope,
        Excitation,
        Link,
        Sensors,
        SurfacePort,
        load_config,
        to_toml,
    )

    calibration = {name: Calibration(poly=(-100.0, 0.2)) for name in SurfacePort().calibration}
    calibration["rudder"] = Calibration(table=((0.0, -30.0), (1023.0, 30.0)))
    config = Config(
        excitation=Excitation(envelope=Envelope(min_airspeed=18.5, max_altitude_loss_m=93.0)),
        sensors=Sensors(surfaces=SurfacePort(port="/tmp/surfaces", calibration=calibration)),
        link=Link(port="/tmp/xbee", peer="0013a20040a1b2c3", key_file="k"),
    )
    text = to_toml(config)
    assert "[link]" in text
    assert "max_altitude_loss_m = 93.0" in text
    assert "baud" not in text.split("[link]")[1].split("[")[0]  # defaults left out
    path = tmp_path / "agent.toml"
    path.write_text(text)
    assert load_config(path) == config
    assert to_toml(Config()) == ""


def test_the_configuration_reference_is_current_and_every_key_is_described():
    """docs/configuration.md is `sysid config reference`'s output: regenerate it with
    `.venv/bin/sysid config reference > docs/configuration.md` when a key changes."""
    from pathlib import Path

    from agent.cli.config_check import configuration_reference

    text = configuration_reference()
    docs = Path(__file__).resolve().parents[1] / "docs" / "configuration.md"
    assert docs.read_text() == text, "docs/configuration.md is stale: regenerate it"
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    assert len(rows) > 100
    cells = [row.split(" | ") for row in rows]  # key, type, default, description
    undescribed = [c[0] for c in cells if not c[-1].strip(" |")]
    assert not undescribed, undescribed


def test_the_config_and_the_identification_core_bound_decimation_alike():
    from agent.config import MAX_DECIMATION
    from agent.ident import preprocess

    assert MAX_DECIMATION == preprocess.MAX_DECIMATION


def test_keygen_makes_a_key_the_link_takes_and_never_writes_over_one(tmp_path, capsys):
    """`sysid keygen`: a key load_key takes (strong, mode 0600) with its fingerprint. Bad
    input tried: the same file again (a key in use would be lost: refused, exit 2, the file
    unchanged), a folder that does not exist; under --json one object on every path."""
    import json

    from agent.config import load_key
    from agent.link.codec import key_fingerprint

    path = tmp_path / "link.key"
    assert main(["keygen", str(path), "--json"]) == 0
    made = json.loads(capsys.readouterr().out)
    key = load_key(path)
    assert len(key) == 32
    assert made == {"file": str(path), "fingerprint": key_fingerprint(key)}
    assert path.stat().st_mode & 0o777 == 0o600
    before = path.read_text()
    assert main(["keygen", str(path), "--json"]) == 2
    error = json.loads(capsys.readouterr().out)["error"]
    assert "exists: a key is never written over" in error["message"]
    assert path.read_text() == before
    assert main(["keygen", str(tmp_path / "no" / "such" / "k")]) == 2
    assert "cannot be created" in capsys.readouterr().err
    assert main(["keygen", str(tmp_path / "other.key")]) == 0
    assert load_key(tmp_path / "other.key") != key  # drawn anew
