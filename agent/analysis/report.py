"""`sysid report`: one HTML page with PNG figures (matplotlib, Agg) for a set of excitation
logs — thesis figures 6.2–6.5 and 6.13 and what a flight-test engineer checks next to them:

- measured against identified time histories per output, each with its TIC (figs. 6.2–6.4);
- the eigenvalues of every excitation's model in the s-plane, the nominal model's highlighted
  (fig. 6.5);
- the Hankel singular values with the chosen order;
- FRFs (Bode) of each identified model against the data's own estimate (H1: cross-spectrum
  over input auto-spectrum, Welch averaging), per input–output pair;
- the input spectra and their relative peak factors;
- the mode table with the quality indexes.

The identification is the agent's worker job, so the page shows what the aircraft computed.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import scipy.signal

from agent.analysis.analyze import Case
from agent.excitation.signals import relative_peak_factor
from agent.ident import Experiment
from agent.ident.convert import StateSpace
from agent.ident.fit import fit
from agent.ident.job import Outcome
from agent.ident.preprocess import preprocess

DPI = 90
COLOURS = plt.rcParams["axes.prop_cycle"].by_key()["color"]


def _prepared(case: Case, outcome: Outcome) -> tuple[list[Experiment], float]:
    p = outcome.preprocessing
    batch, prep = preprocess(
        [Experiment(u, y) for u, y in case.job.experiments],
        case.job.record_dt,
        decimation=p["factor"],
        band_hz=p["band_hz"],
        held_inputs=p["held_inputs"],
        smoothing_s=p["smoothing_s"],
    )
    return batch, prep.dt


def _model(outcome: Outcome) -> StateSpace:
    r = outcome.result
    return StateSpace(*(np.asarray(r[k], dtype=float) for k in ("A", "B", "C", "D")))


def time_histories(case: Case, outcome: Outcome, path: Path) -> None:
    batch, dt = _prepared(case, outcome)
    result = fit(_model(outcome), batch)
    outputs = case.job.outputs
    fig, axes = plt.subplots(len(outputs), 1, figsize=(9, 1.9 * len(outputs)), sharex=True)
    axes = np.atleast_1d(axes)
    for j, (ax, name) in enumerate(zip(axes, outputs, strict=True)):
        for k, (exp, predicted) in enumerate(zip(batch, result.predictions, strict=True)):
            t = np.arange(exp.length) * dt
            ax.plot(t, exp.y[:, j], color="0.3", lw=1.0, label="measured" if k == 0 else None)
            ax.plot(
                t,
                predicted[:, j],
                color=COLOURS[0],
                lw=1.2,
                ls="--",
                label="identified" if k == 0 else None,
            )
        ax.set_ylabel(name)
        ax.text(
            0.99,
            0.9,
            f"TIC {result.tic[j]:.3f}",
            transform=ax.transAxes,
            ha="right",
            va="top",
            fontsize=9,
        )
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    axes[0].set_title(f"excitation {case.label}: TIC_avg {result.tic_avg:.3f}")
    axes[-1].set_xlabel("time (s, deviations from trim)")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def s_plane(
    cases: Sequence[Case], outcomes: Sequence[Outcome], nominal: dict | None, path: Path
) -> None:
    fig, ax = plt.subplots(figsize=(7, 5))
    for k, (case, outcome) in enumerate(zip(cases, outcomes, strict=True)):
        if not outcome.ok:
            continue
        lam = np.array([complex(*m["eigenvalue"]) for m in outcome.result["modes"]])
        lam = np.concatenate([lam, lam[lam.imag != 0].conj()])
        ax.plot(
            lam.real,
            lam.imag,
            "x",
            color=COLOURS[k % len(COLOURS)],
            ms=7,
            label=f"excitation {case.label}",
        )
    if nominal is not None:
        lam = np.array([complex(*m["eigenvalue"]) for m in nominal["modes"]])
        lam = np.concatenate([lam, lam[lam.imag != 0].conj()])
        ax.plot(
            lam.real,
            lam.imag,
            "o",
            mfc="none",
            mec="k",
            ms=12,
            mew=2,
            label=f"nominal {nominal['model_id']}",
        )
    ax.axvline(0, color="0.5", lw=0.8)
    ax.axhline(0, color="0.5", lw=0.8)
    ax.set_xlabel("real (1/s)")
    ax.set_ylabel("imaginary (rad/s)")
    ax.set_title("eigenvalues of every excitation")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def hankel(cases: Sequence[Case], outcomes: Sequence[Outcome], path: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for k, (case, outcome) in enumerate(zip(cases, outcomes, strict=True)):
        if not outcome.ok:
            continue
        sv = np.asarray(outcome.result["singular_values"], dtype=float)
        n = outcome.result["order"]
        colour = COLOURS[k % len(COLOURS)]
        ax.semilogy(
            np.arange(1, sv.size + 1),
            sv,
            ".-",
            color=colour,
            label=f"excitation {case.label} (n = {n})",
        )
        ax.axvline(n + 0.5, color=colour, ls=":", lw=1)
    ax.set_xlabel("index")
    ax.set_ylabel("Hankel singular value")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def bode(case: Case, outcome: Outcome, path: Path) -> None:
    """Each input → output pair: the model's FRF against the data's H1 estimate."""
    batch, dt = _prepared(case, outcome)
    model = _model(outcome)
    inputs, outputs = case.job.inputs, case.job.outputs
    u = np.vstack([e.u for e in batch])
    y = np.vstack([e.y for e in batch])
    nper = min(512, u.shape[0] // 4)
    size = (2.6 * len(outputs), 2.6 * len(inputs))
    fig, axes = plt.subplots(2 * len(inputs), len(outputs), figsize=size, squeeze=False)
    eye = np.eye(model.A.shape[0])
    for i, iname in enumerate(inputs):
        f, puu = scipy.signal.welch(u[:, i], fs=1 / dt, nperseg=nper)
        grid = np.logspace(np.log10(f[1]), np.log10(f[-1]), 200)
        z = np.exp(2j * np.pi * grid * dt)
        for j, oname in enumerate(outputs):
            _, puy = scipy.signal.csd(u[:, i], y[:, j], fs=1 / dt, nperseg=nper)
            h1 = puy / np.where(puu > 0, puu, np.nan)
            hm = np.array(
                [
                    model.C[j] @ np.linalg.solve(zk * eye - model.A, model.B[:, i]) + model.D[j, i]
                    for zk in z
                ]
            )
            band = puu > 1e-3 * puu.max()  # where the input put power: the estimate means something
            mag, ph = axes[2 * i, j], axes[2 * i + 1, j]
            mag.loglog(f[band], np.abs(h1[band]), ".", color="0.4", ms=3, label="data (H1)")
            mag.loglog(grid, np.abs(hm), color=COLOURS[0], label="model")
            ph.semilogx(f[band], np.degrees(np.angle(h1[band])), ".", color="0.4", ms=3)
            ph.semilogx(grid, np.degrees(np.angle(hm)), color=COLOURS[0])
            mag.set_title(f"{iname} → {oname}", fontsize=8)
            ph.set_xlabel("Hz", fontsize=8)
            ph.set_ylabel("°", fontsize=8)
            for ax in (mag, ph):
                ax.tick_params(labelsize=7)
                ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
                ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def input_spectra(case: Case, dt: float, path: Path) -> list[tuple[str, float]]:
    """Power spectral density of each input; returns each input's RPF."""
    u = np.vstack([u for u, _ in case.job.experiments])
    fig, ax = plt.subplots(figsize=(7, 3.2))
    rpf = []
    for i, name in enumerate(case.job.inputs):
        f, p = scipy.signal.welch(u[:, i], fs=1 / dt, nperseg=min(1024, u.shape[0] // 2))
        ax.semilogy(f[1:], p[1:], label=name)
        rpf.append((name, relative_peak_factor(u[:, i])))
    ax.set_xlabel("Hz")
    ax.set_ylabel("PSD")
    ax.set_xlim(0, min(5.0, 0.5 / dt))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"excitation {case.label}: inputs")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return rpf


def _fmt(value, spec: str = "{:.2f}") -> str:
    return "–" if value is None else spec.format(value)


def mode_table(outcome: Outcome) -> str:
    head = ("mode", "eigenvalue", "f (Hz)", "ζ", "τ (s)", "MSV", "MCI", "MOI", "EMAC", "MPC", "CMI")
    rows = []
    for m in outcome.result["modes"]:
        lam = complex(*m["eigenvalue"])
        cells = (
            m["name"] or "–",
            f"{lam.real:+.3f}{lam.imag:+.3f}j",
            _fmt(m["frequency_rad_s"] / (2 * np.pi), "{:.3f}"),
            _fmt(m["damping"]),
            _fmt(m["time_constant_s"]),
            _fmt(m["msv"], "{:.3g}"),
            _fmt(m["mci"], "{:.3g}"),
            _fmt(m["moi"], "{:.3g}"),
            _fmt(m["emac"], "{:.0f}"),
            _fmt(m["mpc"], "{:.0f}"),
            _fmt(m["cmi"], "{:.0f}"),
        )
        rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    header = "<tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>"
    return f"<table>{header}{''.join(rows)}</table>"


CSS = """body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #bbb;padding:2px 6px;
font-size:0.85em;text-align:right}th{background:#eee}img{max-width:100%;display:block;
margin:0.5em 0}h2{border-bottom:2px solid #ccc;margin-top:2em}.fail{color:#b00}"""


def write(
    directory: Path,
    logs: Sequence[Path],
    cases: Sequence[Case],
    outcomes: Sequence[Outcome],
    nominal: dict | None = None,
) -> Path:
    """The report in `directory` (index.html and its PNGs); returns the page's path."""
    directory.mkdir(parents=True, exist_ok=True)
    parts = [
        f"<h1>suas-sysid report</h1><p>{len(logs)} log(s): "
        + ", ".join(html.escape(Path(p).name) for p in logs)
        + "</p>"
    ]
    s_plane(cases, outcomes, nominal, directory / "s_plane.png")
    hankel(cases, outcomes, directory / "hankel.png")
    parts.append(
        '<h2>Eigenvalues</h2><img src="s_plane.png" alt="s-plane">'
        '<h2>Hankel singular values</h2><img src="hankel.png" alt="Hankel">'
    )
    for case, outcome in zip(cases, outcomes, strict=True):
        tag = f"excitation_{case.label}"
        parts.append(f"<h2>Excitation {html.escape(case.label)}</h2>")
        if not outcome.ok:
            parts.append(
                f'<p class="fail">identification failed: {html.escape(outcome.reason)}</p>'
            )
            continue
        r = outcome.result
        parts.append(
            f"<p>p = {r['markov']}, n = {r['order']}, TIC_avg = {r['tic_avg']:.3f}, "
            f"{'stable' if r['stable'] else 'not stable'}</p>"
        )
        parts.append(mode_table(outcome))
        time_histories(case, outcome, directory / f"{tag}_time.png")
        bode(case, outcome, directory / f"{tag}_bode.png")
        rpf = input_spectra(case, case.job.record_dt, directory / f"{tag}_inputs.png")
        rpf_text = ", ".join(f"{n} {v:.2f}" for n, v in rpf)
        parts.append(
            f'<img src="{tag}_time.png" alt="time histories {tag}">'
            f'<img src="{tag}_bode.png" alt="Bode {tag}">'
            f"<p>Relative peak factors: {rpf_text}</p>"
            f'<img src="{tag}_inputs.png" alt="input spectra {tag}">'
        )
    page = directory / "index.html"
    page.write_text(
        f'<!doctype html><html><head><meta charset="utf-8"><title>suas-sysid '
        f"report</title><style>{CSS}</style></head><body>{''.join(parts)}"
        "</body></html>"
    )
    return page
