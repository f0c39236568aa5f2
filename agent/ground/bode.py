"""A frequency response in a terminal: one input → output pair of a result, the measured
response the aircraft sent (`FrfReport`: magnitude, phase and coherence at the frequencies
the input excited) with the identified model's over it, computed here from the result's
matrices. Measured points with coherence below COHERENCE_MIN are drawn apart (×, grey) and
counted beneath: there the measurement does not judge the model."""

from __future__ import annotations

import numpy as np
from rich.text import Text
from textual.widget import Widget

from agent.ident.frf import COHERENCE_MIN, model_response
from agent.link import messages

MEASURED = ("●", "bold white")
LOW = ("×", "grey50")
MODEL = ("·", "cyan")
AXIS = "grey35"
LABEL_W = 7


def model_of(result: messages.Result, report: messages.FrfReport, freqs: np.ndarray):
    """The result's response for the report's pair at `freqs` (Hz)."""
    i, j = result.inputs.index(report.input), result.outputs.index(report.output)
    return model_response(result.A, result.B, result.C, result.D, result.dt, freqs)[:, j, i]


def plot(report: messages.FrfReport, result: messages.Result | None, width: int) -> Text:
    """Magnitude (dB), phase (°) and coherence against frequency (log), as text."""
    width = max(width, 40)
    cols = width - LABEL_W - 1
    f = np.asarray(report.freq_hz)
    text = Text()
    text.append(
        f"{report.model_id}  {report.input} → {report.output}   "
        f"{len(f)} frequencies, {_averaging(report)}\n",
        "bold",
    )
    if f.size == 0:
        text.append("the input excited no frequency in this model's data", "yellow")
        return text
    lo, hi = np.log10(f.min() / 1.2), np.log10(f.max() * 1.2)
    grid = np.logspace(lo, hi, cols)
    h = model_of(result, report, grid) if result is not None else None
    gamma = np.array([np.nan if g is None else g for g in report.coherence])
    good = ~(gamma < COHERENCE_MIN)
    mag = np.asarray(report.mag_db)
    model_mag = None if h is None else 20 * np.log10(np.abs(h))
    top = max(mag.max(), -np.inf if model_mag is None else model_mag.max()) + 3
    bottom = min(mag.min(), np.inf if model_mag is None else model_mag.min()) - 3

    def column(x: float) -> int:
        return round((np.log10(x) - lo) / (hi - lo) * (cols - 1))

    panels = [
        ("dB", 8, (bottom, top), mag, model_mag),
        ("°", 5, (-180.0, 180.0), np.asarray(report.phase_deg), _phase(h)),
        ("γ²", 3, (0.0, 1.0), gamma, None),
    ]
    for unit, rows, (y0, y1), measured, model in panels:
        cells = [[(" ", "")] * cols for _ in range(rows)]

        def row(y: float, rows=rows, y0=y0, y1=y1) -> int:
            return round((y1 - y) / (y1 - y0) * (rows - 1))

        if unit == "γ²":
            r = row(COHERENCE_MIN)
            cells[r] = [("╌", "red")] * cols
        if model is not None:
            for c, y in enumerate(model):
                if np.isfinite(y) and y0 <= y <= y1:
                    cells[row(y)][c] = MODEL
        for x, y, ok in zip(f, measured, good, strict=True):
            if np.isfinite(y):
                cells[min(rows - 1, max(0, row(y)))][column(x)] = MEASURED if ok else LOW
        for k, line in enumerate(cells):
            label = f"{y1:.0f}" if k == 0 else f"{y0:.0f}" if k == rows - 1 else ""
            if unit == "γ²":
                label = "1" if k == 0 else "0" if k == rows - 1 else ""
            name = unit if k == 0 else ""
            text.append(f"{label:>{LABEL_W - 3}} {name:<2}│", AXIS)
            for char, style in line:
                text.append(char, style)
            text.append("\n")
    left, right = f"{10**lo:.2g} Hz", f"{10**hi:.2g} Hz"
    text.append(" " * (LABEL_W + 1) + left + " " * max(1, cols - len(left) - len(right)) + right)
    low = int(np.sum(~good))
    text.append("\n")
    text.append(
        f"{MEASURED[0]} measured  {LOW[0]} γ² < {COHERENCE_MIN}  {MODEL[0]} model   ", "grey70"
    )
    if low:
        text.append(
            f"γ² low at {low} of {f.size}: not to be trusted there",
            "yellow" if low < f.size / 2 else "bold yellow",
        )
    return text


def _phase(h) -> np.ndarray | None:
    if h is None:
        return None
    phase = np.degrees(np.angle(h))
    jumps = np.abs(np.diff(phase)) > 180  # no dots dragged across a wrap
    phase[1:][jumps] = np.nan
    return phase


def _averaging(report: messages.FrfReport) -> str:
    if report.averaging == "periods":
        return f"averaged over {report.segments} periods"
    return f"{report.segments} Welch segments"


class Bode(Widget):
    """One pair's frequency response, or what to do to get it."""

    DEFAULT_CSS = "Bode { height: 22; min-width: 40; }"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.report: messages.FrfReport | None = None
        self.result: messages.Result | None = None
        self.hint = "pick a pair and press f: the aircraft sends its measured frequency response"

    def show(self, report, result, hint: str | None = None) -> None:
        self.report, self.result = report, result
        if hint is not None:
            self.hint = hint
        self.refresh()

    def render(self) -> Text:
        if self.report is None:
            return Text(self.hint, "grey50")
        return plot(self.report, self.result, self.size.width)
