"""`sysid report`: one HTML page with PNG figures (matplotlib, Agg) for a set of excitation
logs — thesis figures 6.2–6.5 and 6.13 and what a flight-test engineer checks next to them:

- measured against identified time histories per output, each with its TIC (figs. 6.2–6.4);
- the eigenvalues of every excitation's model in the s-plane, the nominal model's highlighted
  (fig. 6.5), and per excitation its modes with their Cramér–Rao ellipses against the nominal
  and the earlier excitations (`splane`: inline SVG, each mode's row on hover);
- the Hankel singular values with the chosen order;
- frequency responses of every input–output pair: the measured response at the frequencies
  the input excited, with its coherence, and the identified model's over it
  (`agent.ident.frf`: averaged over periods or Welch segments, H = S_yu S_uu⁻¹ per bin);
- the input spectra and their relative peak factors;
- the mode table with the quality indexes;
- the stability and control derivatives with their standard errors (`derivatives`), and
  their CSV.

The identification is the agent's worker job, so the page shows what the aircraft computed.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import BinaryIO

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import scipy.signal

from agent import tune
from agent.analysis import derivatives, splane
from agent.analysis.analyze import Case
from agent.config import Channels, Config
from agent.excitation.signals import relative_peak_factor
from agent.ident import Experiment, frf
from agent.ident.document import ResultDocument
from agent.ident.fit import fit
from agent.ident.frf import MeasuredResponse
from agent.ident.job import Outcome, of_result, prepared
from agent.models import StoredModel
from agent.outputs import Outputs

DPI = 90
COLOURS = plt.rcParams["axes.prop_cycle"].by_key()["color"]


def _prepared(case: Case, outcome: Outcome) -> tuple[list[Experiment], float]:
    """The case's experiments as its model sees them: its channels (the aircraft method leaves
    out what the record did not move), preprocessed as its data were."""
    job, result = case.job, outcome.result
    experiments = of_result(result, job.inputs, job.outputs, job.experiments)
    batch, prep = prepared(result.preprocessing, job.record_dt, experiments)
    return batch, prep.dt


def time_histories(case: Case, outcome: Outcome, path: BinaryIO) -> None:
    batch, dt = _prepared(case, outcome)
    result = fit(outcome.result.model(), batch)
    outputs = outcome.result.outputs
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
    fig.savefig(path, dpi=DPI, format="png")
    plt.close(fig)


def s_plane(cases: Sequence[Case], outcomes: Sequence[Outcome], nominal: StoredModel | None) -> str:
    """Every excitation's modes, one colour each, and the nominal's: an inline SVG."""
    marks = []
    for k, (case, outcome) in enumerate(zip(cases, outcomes, strict=True)):
        if outcome.ok:
            colour = splane.COLOURS[k % len(splane.COLOURS)]
            marks += [
                replace(m, colour=colour)
                for m in splane.marks_of(
                    outcome.result.modes, "this", f"excitation {case.label}", _anchor(case)
                )
            ]
    if nominal is not None:
        marks += splane.marks_of(nominal.modes, "nominal", f"nominal {nominal.model_id}")
    return splane.svg(marks, "eigenvalues of every excitation")


def excitation_s_plane(
    k: int, cases: Sequence[Case], outcomes: Sequence[Outcome], nominal: StoredModel | None
) -> str:
    """Excitation k's modes with their ellipses, the nominal's, and the earlier excitations'
    faded."""
    case, outcome = cases[k], outcomes[k]
    marks = []
    for earlier, done in zip(cases[:k], outcomes[:k], strict=True):
        if done.ok:
            marks += splane.marks_of(
                done.result.modes, "earlier", f"excitation {earlier.label}", _anchor(earlier)
            )
    if nominal is not None:
        marks += splane.marks_of(nominal.modes, "nominal", f"nominal {nominal.model_id}")
    marks += splane.marks_of(
        outcome.result.modes, "this", f"excitation {case.label}", _anchor(case)
    )
    return splane.svg(marks, f"excitation {case.label}: its modes, the nominal's, earlier ones")


def _summary(r: ResultDocument) -> str:
    """The model in one line: what its method chose (OKID's p, or the aircraft method's
    structure), the order, the fit, stability."""
    if r.okid is not None:
        chosen = f"p = {r.okid.markov}, "
    elif r.aircraft is not None:
        chosen = f"whole-aircraft method ({r.aircraft.model}), "
    else:
        chosen = ""
    stable = "stable" if r.stable else "not stable"
    return f"{chosen}n = {r.order}, TIC_avg = {r.tic_avg:.3f}, {stable}"


def _anchor(case: Case) -> str:
    return f"mode-{case.label}"


def hankel(cases: Sequence[Case], outcomes: Sequence[Outcome], path: BinaryIO) -> None:
    """The Hankel singular values of every OKID/ERA model, each with its chosen order (the
    whole-aircraft method has none: it realises no Hankel matrix)."""
    fig, ax = plt.subplots(figsize=(7, 3.5))
    drawn = False
    for k, (case, outcome) in enumerate(zip(cases, outcomes, strict=True)):
        if not outcome.ok or outcome.result.okid is None:
            continue
        drawn = True
        sv = np.asarray(outcome.result.okid.singular_values, dtype=float)
        n = outcome.result.order
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
    if drawn:
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no OKID/ERA model", transform=ax.transAxes, ha="center")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI, format="png")
    plt.close(fig)


def unwrapped_phase(h: np.ndarray) -> np.ndarray:
    """The phase of a response along its frequency grid, in degrees, unwrapped (continuous, as
    CIFER and SIDPAC plot it: a lag past −180° reads as −200°, not +160°), its lowest
    frequency's in (−180°, 180°]."""
    return np.degrees(np.unwrap(np.angle(h)))


def nearest_branch(
    f: np.ndarray, phase: np.ndarray, grid: np.ndarray, line: np.ndarray
) -> np.ndarray:
    """Measured phases (degrees, any branch) each moved by whole turns to the branch nearest
    the model's unwrapped `line` over `grid` at its frequency: the points sit on the line they
    are judged against, not 360° away from it."""
    reference = np.interp(np.log(f), np.log(grid), line)
    return phase + 360.0 * np.round((reference - phase) / 360.0)


def frequency_responses(
    case: Case, outcome: Outcome, path: BinaryIO
) -> tuple[MeasuredResponse, list]:
    """Each input → output pair at the frequencies the input excited: the measured response
    (magnitude in dB, phase) and its coherence, the identified model's response over it.
    Points below COHERENCE_MIN are drawn apart (×). Returns the measured response and the
    pairs whose coherence is low at most of their input's frequencies."""
    batch, dt = _prepared(case, outcome)
    measured = frf.measured(batch, dt)
    model = outcome.result.model()
    inputs, outputs = outcome.result.inputs, outcome.result.outputs
    size = (2.4 * len(outputs), 2.9 * len(inputs))
    fig, axes = plt.subplots(
        3 * len(inputs),
        len(outputs),
        figsize=size,
        squeeze=False,
        sharex="col",
        gridspec_kw={"height_ratios": [3, 2, 1] * len(inputs)},
    )
    if measured.freqs.size:
        grid = np.logspace(np.log10(measured.freqs.min()), np.log10(measured.freqs.max()), 300)
    else:
        grid = np.logspace(-1, np.log10(0.45 / dt), 300)
    hm = frf.model_response(model.A, model.B, model.C, model.D, dt, grid)
    low = []
    for i, iname in enumerate(inputs):
        excited = measured.excited(i)
        f = measured.freqs[excited]
        for j, oname in enumerate(outputs):
            mag, ph, coh = axes[3 * i, j], axes[3 * i + 1, j], axes[3 * i + 2, j]
            mag.set_title(f"{iname} → {oname}", fontsize=8)
            mag.semilogx(grid, 20 * np.log10(np.abs(hm[:, j, i])), color=COLOURS[0], lw=1.2)
            line = unwrapped_phase(hm[:, j, i])
            ph.semilogx(grid, line, color=COLOURS[0], lw=1.2)
            if f.size:
                h = measured.H[excited, j, i]
                g = measured.coherence[excited, j, i]
                good = ~(g < frf.COHERENCE_MIN)
                for keep, marker, colour in ((good, ".", "0.25"), (~good, "x", "0.65")):
                    mag.semilogx(
                        f[keep], 20 * np.log10(np.abs(h[keep])), marker, color=colour, ms=3
                    )
                    phase = nearest_branch(f[keep], np.degrees(np.angle(h[keep])), grid, line)
                    ph.semilogx(f[keep], phase, marker, color=colour, ms=3)
                    coh.semilogx(f[keep], g[keep], marker, color=colour, ms=3)
                share = measured.low_coherence(i, j)
                if share is not None and share > 0.5:
                    low.append((iname, oname, share))
            else:
                mag.text(0.5, 0.5, "not excited", transform=mag.transAxes, ha="center", fontsize=8)
            coh.axhline(frf.COHERENCE_MIN, color="tab:red", lw=0.8, ls="--")
            coh.set_ylim(0, 1.05)
            if j == 0:
                mag.set_ylabel("dB", fontsize=8)
                ph.set_ylabel("°", fontsize=8)
                coh.set_ylabel("γ²", fontsize=8)
            if i == len(inputs) - 1:
                coh.set_xlabel("Hz", fontsize=8)
            for ax in (mag, ph, coh):
                ax.tick_params(labelsize=7)
                ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
                ax.grid(alpha=0.3, which="both")
    fig.suptitle(
        f"excitation {case.label}: measured (·; × where γ² < {frf.COHERENCE_MIN}) and model (—); "
        + _averaging(measured),
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=DPI, format="png")
    plt.close(fig)
    return measured, low


def _averaging(measured: MeasuredResponse) -> str:
    if measured.averaging == "periods":
        return f"averaged over {measured.segments} periods of {measured.segment_s:.1f} s"
    return f"{measured.segments} half-overlapping Hann segments of {measured.segment_s:.1f} s"


def input_spectra(case: Case, dt: float, path: BinaryIO) -> list[tuple[str, float]]:
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
    fig.savefig(path, dpi=DPI, format="png")
    plt.close(fig)
    return rpf


def _derivatives(case: Case, outcome: Outcome, directory: Path, tag: str, outputs: Outputs) -> str:
    """The stability and control derivatives with their standard errors, and their CSV."""
    table = derivatives.from_result(outcome.result)
    if table is None:
        return (
            "<h3>Derivatives</h3><p>None: the model is not in output coordinates (the outputs "
            "do not determine its state).</p>"
        )
    name = f"{tag}_derivatives.csv"
    outputs.write_text(directory / name, derivatives.to_csv([(case.label, table)]))
    known = "" if np.isfinite(table.std).any() else " (no standard errors: not refined)"
    return (
        f"<h3>Derivatives</h3><p>Row: the output whose rate; column: the state or input; "
        f"value ± Cramér–Rao standard error, in % below; grey: fixed, not estimated; red: "
        f"σ over {100 * derivatives.POOR:.0f} % of the value{known}. "
        f'<a href="{name}">CSV</a></p>{derivatives.to_html(table)}'
    )


def _frf_note(measured: MeasuredResponse, low: list) -> str:
    """What the frequency-response figure shows, and where its coherence is low."""
    text = (
        f"<p>Measured at the frequencies each input excited ({_averaging(measured)}), the "
        f"identified model's response over it. Coherence γ² below {frf.COHERENCE_MIN} "
        "(×): the measured response is not to be trusted there.</p>"
    )
    if low:
        pairs = ", ".join(
            f"{html.escape(i)} → {html.escape(o)} ({100 * share:.0f} %)" for i, o, share in low
        )
        text += (
            f'<p class="warn">Low coherence at most of the input\'s frequencies: {pairs}. '
            "These pairs do not judge the model: the output there is noise, turbulence or "
            "another input's response.</p>"
        )
    return text


def _fmt(value, spec: str = "{:.2f}") -> str:
    return "–" if value is None else spec.format(value)


def mode_table(outcome: Outcome, anchor: str = "mode") -> str:
    """The modes with their quality indexes; row k has the id `{anchor}-{k}` (the s-plane
    links to it)."""
    head = ("mode", "eigenvalue", "f (Hz)", "ζ", "τ (s)", "MSV", "MCI", "MOI", "EMAC", "MPC", "CMI")
    rows = []
    for k, m in enumerate(outcome.result.modes):
        lam = complex(*m.eigenvalue)
        cells = (
            m.name or "–",
            f"{lam.real:+.3f}{lam.imag:+.3f}j",
            _fmt(m.frequency_hz, "{:.3f}"),
            _fmt(m.damping),
            _fmt(m.time_constant_s),
            _fmt(m.msv, "{:.3g}"),
            _fmt(m.mci, "{:.3g}"),
            _fmt(m.moi, "{:.3g}"),
            _fmt(m.emac, "{:.0f}"),
            _fmt(m.mpc, "{:.0f}"),
            _fmt(m.cmi, "{:.0f}"),
        )
        cells_html = "".join(f"<td>{html.escape(c)}</td>" for c in cells)
        rows.append(f'<tr id="{anchor}-{k}">{cells_html}</tr>')
    header = "<tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>"
    return f"<table>{header}{''.join(rows)}</table>"


CSS = """body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #bbb;padding:2px 6px;
font-size:0.85em;text-align:right}th{background:#eee}img{max-width:100%;display:block;
margin:0.5em 0}h2{border-bottom:2px solid #ccc;margin-top:2em}.fail{color:#b00}.warn{color:#a60}
.fixed{color:#999;font-style:italic}.poor{color:#b00}tr:target{background:#ffe9a0}
svg.splane{display:block;margin:0.5em 0}svg.splane a:hover{opacity:0.7}"""


def gains(
    case: Case, outcome: Outcome, config: Config, directory: Path, tag: str, outputs: Outputs
) -> str:
    """ArduPlane's FBWA gains designed from the model (agent.tune, as `sysid tune` with the
    config's surfaces and the nominal servo), their predicted loops as a table, and each
    axis's whole loop (Bode, broken at the actuator) and predicted step as a PNG."""
    result = outcome.result
    head = "<h3>ArduPlane gains from this model</h3>"
    cont = result.continuous
    if cont is None or result.coordinates != "outputs":
        return f"{head}<p>None: no continuous model in output coordinates.</p>"
    trim = _trim(case, result, config.identification.channels)
    model = tune.Model(
        id=case.label,
        inputs=list(result.inputs),
        outputs=list(result.outputs),
        A=np.asarray(cont.A, dtype=float),
        B=np.asarray(cont.B, dtype=float),
        C=np.asarray(cont.C, dtype=float),
        trim={k: float(v) for k, v in trim.items()},
    )
    try:
        designed = tune.design(model, config.identification.channels, config.excitation.surfaces)
    except tune.TuneError as exc:
        return f"{head}<p>None: {html.escape(str(exc))}</p>"
    rows = []
    for t in designed.tunes:
        m = t.attitude_loop
        values = ", ".join(f"{k} {v:g}" for k, v in t.params.items())
        rows.append(
            f"<tr><td>{t.axis}</td><td>{values}</td><td>{_fmt(m.crossover_rad_s)}</td>"
            f"<td>{_fmt(m.phase_deg, '{:.0f}')}°</td><td>{_fmt(m.gain_db, '{:.1f}')} dB</td>"
            f"<td>{_fmt(m.rejection_rad_s)}</td><td>{t.rise_s:.2f} s</td>"
            f"<td>{t.overshoot_pct:.1f} %</td></tr>"
        )
    yaw = designed.yaw
    if yaw is not None:
        rows.append(
            f"<tr><td>yaw damper</td><td>YAW2SRV_DAMP {yaw.params['YAW2SRV_DAMP']:g}</td>"
            f"<td colspan=6>Dutch roll ζ {yaw.zeta(yaw.before):.2f} → {yaw.zeta(yaw.after):.2f} "
            f"with the roll loop closed</td></tr>"
        )
    name = f"{tag}_gains.png"
    with outputs.open(directory / name) as handle:
        loop_figure(designed, handle)
    notes = [*designed.notes, *designed.refused, *(n for t in designed.tunes for n in t.notes)]
    return (
        f"{head}<p>As <code>sysid tune</code> designs them (docs/tuning.md), at "
        f"{designed.eas:.1f} m/s, SCALING_SPEED {designed.scaling_speed:.1f}; the servo's lag "
        "and delay nominal (the run's measured ones: <code>sysid tune --exec-log</code>).</p>"
        "<table><tr><th>axis</th><th>gains</th><th>crossover rad/s</th><th>phase margin</th>"
        "<th>gain margin</th><th>rejection rad/s</th><th>rise</th><th>overshoot</th></tr>"
        + "".join(rows)
        + "</table>"
        + "".join(f"<p>{html.escape(n)}</p>" for n in notes)
        + f'<img src="{name}" alt="designed loops {tag}">'
    )


def _trim(case: Case, result: ResultDocument, channels: Channels) -> dict[str, float]:
    """The model's trim outputs by channel: the result's own (one record), else the first
    experiment's operating point; the states it does not output (a lateral model's airspeed)
    from that record's flight, their mean."""
    if len(result.trim) == 1:
        return {k: float(v) for k, v in result.trim[0].items()}
    contexts = case.job.contexts
    if not contexts or contexts[0][0] is None:
        return {}
    trim = dict(zip(case.job.outputs, (float(v) for v in contexts[0][0]), strict=True))
    flight = (*contexts[0], None, None)[3] or {}
    roles = {role: getattr(channels, role) for role in ("airspeed", "theta", "phi")}
    for role, values in dict(flight).items():
        name = roles.get(role)
        if name is not None and name not in trim and len(values):
            trim[name] = float(np.mean(values))
    return trim


def loop_figure(designed: tune.Design, path: BinaryIO) -> None:
    """Per designed axis: the whole loop's magnitude and phase (broken at the actuator) and
    its predicted step."""
    # Up to the 50 Hz loop's Nyquist frequency: beyond it the delays' phase only winds on.
    frequencies = tune.FREQUENCIES
    shown = frequencies <= np.pi * tune.LOOP_HZ
    w = frequencies[shown]
    fig, axes = plt.subplots(len(designed.tunes), 3, figsize=(12, 3.2 * len(designed.tunes)))
    axes = np.atleast_2d(axes)
    for row, t in zip(axes, designed.tunes, strict=True):
        plant, actuator = designed.loops[t.axis]
        kw = {"eas": designed.eas, "scaling_speed": designed.scaling_speed}
        whole = tune.loops(t.axis, plant, actuator, t.params, **kw)[1][shown]
        m = t.attitude_loop
        row[0].semilogx(w, 20 * np.log10(np.abs(whole)), color=COLOURS[0])
        row[0].axhline(0.0, color="0.5", lw=0.8)
        row[0].set_ylabel("|L| (dB)")
        row[0].set_title(f"{t.axis}: whole loop, crossover {m.crossover_rad_s:.2f} rad/s")
        phase = np.degrees(np.unwrap(np.angle(whole)))
        if np.isfinite(m.crossover_rad_s):  # the branch where the crossover's lies in (−360°, 0°]
            at = float(np.interp(np.log(m.crossover_rad_s), np.log(w), phase))
            phase -= 360.0 * np.ceil(at / 360.0)
        row[1].semilogx(w, phase, color=COLOURS[0])
        row[1].axhline(-180.0, color="0.5", lw=0.8)
        row[1].set_ylabel("∠L (deg)")
        row[1].set_title(f"phase margin {m.phase_deg:.0f}°, gain margin {m.gain_db:.1f} dB")
        for ax in row[:2]:
            ax.set_xlabel("ω (rad/s)")
            ax.set_ylim(auto=True)
            ax.grid(alpha=0.3, which="both")
            if np.isfinite(m.crossover_rad_s):
                ax.axvline(m.crossover_rad_s, color=COLOURS[1], lw=0.8, ls="--")
        time, angle = tune.step_trace(
            t.axis, plant, actuator, t.params, designed.eas, 1.0, designed.scaling_speed
        )
        row[2].plot(time, angle, color=COLOURS[0])
        row[2].axhline(t.step_deg, color="0.5", lw=0.8)
        row[2].set_xlabel("time (s)")
        row[2].set_ylabel("angle (deg)")
        row[2].set_title(
            f"{t.step_deg:g}° step: rise {t.rise_s:.2f} s, overshoot {t.overshoot_pct:.1f} %"
        )
        row[2].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI, format="png")
    plt.close(fig)


def files(directory: Path, cases: Sequence[Case]) -> list[Path]:
    """Every file `write` may write for `cases` in `directory`."""
    names = ["index.html", "hankel.png"]
    for case in cases:
        tag = _tag(case)
        names += [f"{tag}_{part}" for part in ("time.png", "bode.png", "inputs.png", "gains.png")]
        names.append(f"{tag}_derivatives.csv")
    return [directory / name for name in names]


def _tag(case: Case) -> str:
    return f"excitation_{case.label}"


def write(
    directory: Path,
    logs: Sequence[Path],
    cases: Sequence[Case],
    outcomes: Sequence[Outcome],
    nominal: StoredModel | None = None,
    outputs: Outputs | None = None,
    config: Config | None = None,
) -> Path:
    """The report in `directory` (index.html and its PNGs); returns the page's path. Every
    file is written through `outputs` (the command's, which checked them against its inputs),
    each whole or not at all."""
    outputs = Outputs({}) if outputs is None else outputs
    config = Config() if config is None else config
    for path in files(directory, cases):  # all checked before any is written
        outputs.claimed(path)
    directory.mkdir(parents=True, exist_ok=True)
    parts = [
        f"<h1>suas-sysid report</h1><p>{len(logs)} log(s): "
        + ", ".join(html.escape(Path(p).name) for p in logs)
        + "</p>"
    ]
    with outputs.open(directory / "hankel.png") as handle:
        hankel(cases, outcomes, handle)
    parts.append(
        f"<h2>Eigenvalues</h2>{s_plane(cases, outcomes, nominal)}"
        '<h2>Hankel singular values</h2><img src="hankel.png" alt="Hankel">'
    )
    for k, (case, outcome) in enumerate(zip(cases, outcomes, strict=True)):
        tag = _tag(case)
        parts.append(f"<h2>Excitation {html.escape(case.label)}</h2>")
        if not outcome.ok:
            parts.append(
                f'<p class="fail">identification failed: {html.escape(outcome.reason)}</p>'
            )
            continue
        parts.append(f"<p>{html.escape(_summary(outcome.result))}</p>")
        parts.append(mode_table(outcome, _anchor(case)))
        parts.append(excitation_s_plane(k, cases, outcomes, nominal))
        parts.append(_derivatives(case, outcome, directory, tag, outputs))
        with outputs.open(directory / f"{tag}_time.png") as handle:
            time_histories(case, outcome, handle)
        with outputs.open(directory / f"{tag}_bode.png") as handle:
            measured, low = frequency_responses(case, outcome, handle)
        with outputs.open(directory / f"{tag}_inputs.png") as handle:
            rpf = input_spectra(case, case.job.record_dt, handle)
        rpf_text = ", ".join(f"{n} {v:.2f}" for n, v in rpf)
        parts.append(
            f'<img src="{tag}_time.png" alt="time histories {tag}">'
            f"<h3>Frequency responses</h3>{_frf_note(measured, low)}"
            f'<img src="{tag}_bode.png" alt="Bode {tag}">'
            f"<p>Relative peak factors: {rpf_text}</p>"
            f'<img src="{tag}_inputs.png" alt="input spectra {tag}">'
        )
        parts.append(gains(case, outcome, config, directory, tag, outputs))
    page = directory / "index.html"
    outputs.write_text(
        page,
        f'<!doctype html><html><head><meta charset="utf-8"><title>suas-sysid '
        f"report</title><style>{CSS}</style></head><body>{''.join(parts)}"
        "</body></html>",
    )
    return page
