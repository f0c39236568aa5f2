"""`sysid report` renders in a browser: the page is made from two noisy flights of the A.2
model, opened in headless Chromium, and the screenshot is checked for the figures. The page's
parts are checked for what a flight-test engineer reads off them: the s-planes' modes with
their rows (hover and click), the frequency responses with coherence, the derivative table
and its CSV.

Bad input tried: a nominal model file that is not one (exit 2); a record whose rudder never
moved (its model's figures drawn with the model's own channels).
"""

from __future__ import annotations

import csv
import re
import shutil
import subprocess
import sys
from io import BytesIO
from pathlib import Path

import numpy as np
from matplotlib.image import imread

from agent.analysis.analyze import Case
from agent.analysis.report import frequency_responses, time_histories
from agent.ident import Settings, reference
from agent.ident import job as jobs
from tests.analysis.test_analyze import excitation_logs

ROOT = Path(__file__).resolve().parents[2]
ENV = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1"}


def chromium() -> str:
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    assert found, "Chromium is needed to check the report (make test installs it)"
    return found


def test_the_report_renders_in_headless_chromium(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    excitation_logs(logs, count=2)
    out = tmp_path / "report"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "agent",
            "report",
            str(logs),
            "--axes",
            "lateral",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=180,
        env=ENV,
    )
    assert done.returncode == 0, done.stderr
    page = (out / "index.html").read_text()
    images = sorted(p.name for p in out.glob("*.png"))
    assert images == sorted(
        ["hankel.png"]
        + [f"excitation_{k}_{kind}.png" for k in (1, 2) for kind in ("time", "bode", "inputs")]
    )
    for name in images:
        assert f'src="{name}"' in page
    assert "Dutch roll" in page
    assert "Relative peak factors: aileron" in page
    # The thesis's lateral record has no airspeed: no gains designed (their speed scaling
    # needs it), and said.
    assert page.count("gains from this model</h3><p>None: 1: the model has no trim airspeed") == 1
    # The s-planes: one of every excitation, then one per excitation; each mode a group with
    # its row as a tooltip and a link to that row, which exists.
    assert page.count('<svg class="splane"') == 3
    assert page.count('<g class="mode this"') == 3 * 3 + 3  # overview: 2 × 3; sections: 3 + 3
    assert page.count('<g class="mode earlier"') == 3  # excitation 2's plane: excitation 1's
    assert re.search(r"<title>excitation 1: Dutch roll: λ [-+]\d", page)
    for k in range(3):
        assert f'id="mode-1-{k}"' in page
        assert f'href="#mode-1-{k}"' in page
    assert page.count('class="omega"') >= 6
    assert page.count('class="zeta"') == 3 * 10
    # The frequency responses, with their coherence, and the derivatives with their CSV.
    assert page.count("<h3>Frequency responses</h3>") == 2
    assert "Coherence γ² below 0.6" in page
    for k in (1, 2):
        with (out / f"excitation_{k}_derivatives.csv").open() as handle:
            rows = list(csv.DictReader(handle))
        assert len(rows) == 4 * 6  # β̇, ṗ, ṙ, φ̇ over β, p, r, φ, aileron, rudder
        lp = next(r for r in rows if r["equation"] == "dp/dt" and r["variable"] == "p")
        assert float(lp["value"]) < 0  # roll damping
        assert 0 < float(lp["std"]) < abs(float(lp["value"])) / 5
        assert f'href="excitation_{k}_derivatives.csv"' in page
    pixels = screenshot(tmp_path, (out / "index.html").as_uri(), (1100, 2400))
    assert pixels.shape[:2] == (2400, 1100)
    ink = (pixels < 0.9).any(axis=2)  # anything not (near) white
    # Figures, not just text: plotted lines in several colours over a good part of the page,
    # among them matplotlib's first line colour (#1f77b4), which no text on the page uses.
    assert ink.mean() > 0.02
    colours = np.unique((pixels[ink] * 15).round().astype(int), axis=0)
    assert len(colours) > 30
    blue = np.abs(pixels - np.array([0x1F, 0x77, 0xB4]) / 255).max(axis=2) < 0.06
    assert blue.sum() > 2000
    # The overview s-plane (the first figure, an inline SVG) drew: its region has ink in most
    # rows, its unstable half shaded pink.
    assert ink[220:640].any(axis=1).mean() > 0.8
    pink = np.abs(pixels - np.array([0xFB, 0xEC, 0xEC]) / 255).max(axis=2) < 0.02
    assert pink[220:640].sum() > 5000


def screenshot(tmp_path: Path, uri: str, size: tuple[int, int]) -> np.ndarray:
    """What headless Chromium draws of `uri` in a window of `size` (RGB, 0–1)."""
    shot = tmp_path / f"shot-{size[0]}x{size[1]}.png"
    subprocess.run(
        [
            chromium(),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            f"--screenshot={shot}",
            f"--window-size={size[0]},{size[1]}",
            uri,
        ],
        capture_output=True,
        timeout=120,
        check=True,
    )
    return imread(shot)[..., :3]


def test_the_frequency_response_figure_renders_in_headless_chromium(tmp_path):
    """Every pair's magnitude, phase and coherence panel, the model's line in each, the
    measured points in grey and the coherence threshold in red."""
    logs = tmp_path / "logs"
    logs.mkdir()
    excitation_logs(logs, count=1)
    out = tmp_path / "report"
    command = [sys.executable, "-m", "agent", "report", str(logs), "--axes", "lateral"]
    done = subprocess.run(
        [*command, "--out", str(out)], capture_output=True, text=True, timeout=180, env=ENV
    )
    assert done.returncode == 0, done.stderr
    figure = imread(out / "excitation_1_bode.png")[..., :3]
    pixels = screenshot(tmp_path, (out / "excitation_1_bode.png").as_uri(), figure.shape[1::-1])
    blue = np.abs(pixels - np.array([0x1F, 0x77, 0xB4]) / 255).max(axis=2) < 0.08
    red = (pixels[..., 0] > 0.7) & (pixels[..., 1] < 0.35) & (pixels[..., 2] < 0.35)
    grey = np.abs(pixels - 0.25).max(axis=2) < 0.08
    # Two inputs × four outputs × three panels: the model's line across each panel's columns,
    # the threshold across each coherence panel, the measured points everywhere.
    columns = np.array_split(np.arange(pixels.shape[1]), 4)
    for cols in columns:
        assert blue[:, cols].any(axis=1).sum() > 40
        assert red[:, cols].any(axis=0).mean() > 0.3
    assert grey.sum() > 500
    assert "Frequency responses" in (out / "index.html").read_text()


def test_a_bad_nominal_file_is_refused(tmp_path):
    excitation_logs(tmp_path, count=1)
    (tmp_path / "nominal.json").write_text("{}")
    from tests.capped import sysid

    def report(nominal: str) -> subprocess.CompletedProcess:
        args = ["report", str(tmp_path), "--axes", "lateral", "--out", str(tmp_path / "r")]
        return sysid(*args, "--nominal", nominal, cwd=tmp_path)

    done = report(str(tmp_path / "nominal.json"))
    assert done.returncode == 2
    assert "not a model store file" in done.stderr
    # Bad input tried: /dev/zero as the nominal (its whole read grew until killed).
    done = report("/dev/zero")
    assert done.returncode == 2
    assert "not a model store file (over 16 MiB)" in done.stderr


def test_a_report_file_that_is_a_log_is_refused_before_the_work(tmp_path, capsys):
    """Bad input tried: `report LOG --out DIR` where a file the report writes in DIR (the
    excitation's derivatives CSV) is a hard link to LOG: the log used to be overwritten after
    the identification. Refused at once naming both, the log's bytes unchanged."""
    from agent.cli import main

    (log,) = excitation_logs(tmp_path, count=1)
    before = log.read_bytes()
    out = tmp_path / "report"
    out.mkdir()
    (out / "excitation_1_derivatives.csv").hardlink_to(log)
    assert main(["report", str(log), "--axes", "lateral", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}/excitation_1_derivatives.csv: that is {log}, a log being" in err, err
    assert log.read_bytes() == before
    assert [p.name for p in out.iterdir()] == ["excitation_1_derivatives.csv"]


def test_the_figures_of_a_model_without_a_control_its_record_left_at_trim(tmp_path):
    """Bad input tried: a lateral record whose rudder never moved (its column the trim
    alone). The aircraft method leaves the rudder out of the model; the report draws the
    model's own channels (before, its one-input model met the record's two columns)."""
    model = reference.LATERAL
    record = reference.make_record(model, noise=dict.fromkeys(model.outputs, 1e-3))
    u = record.inputs - record.inputs[0]
    u[:, model.inputs.index("rudder")] = 0.0
    job = jobs.Job(
        model_id="m",
        axes="lateral",
        record_dt=0.02,
        inputs=model.inputs,
        outputs=model.outputs,
        roles=("beta", "p", "r", "phi"),
        experiments=((u, record.outputs - record.outputs[0]),),
        settings=Settings(held_inputs=False),
        input_roles=("aileron", "rudder"),
    )
    outcome = jobs.run(job)
    assert outcome.ok, outcome.reason
    assert outcome.result.inputs == ["aileron"]
    case = Case(label="1", key=(), job=job)
    figure = BytesIO()
    time_histories(case, outcome, figure)
    assert figure.getvalue().startswith(b"\x89PNG")
    bode = BytesIO()
    frequency_responses(case, outcome, bode)
    assert bode.getvalue().startswith(b"\x89PNG")


def test_the_phase_is_read_unwrapped_as_cifer_and_sidpac_plot_it():
    """A third-order lag, 1/(s + 1)³, whose phase falls from 0° to −270°: the model's line is
    continuous (it wrapped to +180° at −180° and jumped across the panel), and measured points
    given on the principal branch are drawn on the line's (−200°, not +160°)."""
    from agent.analysis.report import nearest_branch, unwrapped_phase

    grid = np.logspace(-2, 2, 300)
    h = 1 / (2j * np.pi * grid + 1) ** 3
    line = unwrapped_phase(h)
    np.testing.assert_allclose(line, np.degrees(-3 * np.arctan(2 * np.pi * grid)), atol=1e-6)
    assert line[-1] < -260
    f = np.logspace(-1.5, 1.5, 25)
    exact = np.degrees(-3 * np.arctan(2 * np.pi * f))
    principal = np.degrees(np.angle(1 / (2j * np.pi * f + 1) ** 3))
    assert np.any(principal > 0)  # past −180° the principal branch is positive
    np.testing.assert_allclose(nearest_branch(f, principal, grid, line), exact, atol=1e-6)
