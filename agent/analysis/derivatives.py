"""Stability and control derivatives with their standard errors: the identified continuous
model in output coordinates, one row per output's rate, as the thesis's appendix A writes its
models (ẋ = A x + B u with x the measured outputs), e.g. the lateral row
ṗ = L_β β + L_p p + L_r r + L_δa δa + L_δr δr.

The standard errors are the refinement's Cramér–Rao bounds (`refinement.Ac_std`, `Bc_std`):
a derivative whose error is a large part of its value is not determined by the manoeuvre. An
entry with a zero standard error was not estimated but fixed (the whole-aircraft method fixes
the attitude's kinematics). A model not in output coordinates (ERA's balanced coordinates,
when the outputs do not determine the state) has no such table.

Units are the channels' (angles rad, rates rad/s, airspeed m/s, surfaces deg, throttle µs),
per second: row i, column j is ∂ẏ_i/∂x_j.
"""

from __future__ import annotations

import csv
import html
import io
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.ident.document import ResultDocument

# A derivative whose standard error exceeds this share of its value is marked as poorly
# determined by the manoeuvre.
POOR = 0.5


@dataclass(frozen=True)
class Derivatives:
    equations: tuple[str, ...]  # the outputs whose rate each row gives
    variables: tuple[str, ...]  # the states (the outputs, then any others), then the inputs
    value: np.ndarray  # (rows, variables)
    std: np.ndarray  # (rows, variables); nan: not known (no refinement); 0: fixed

    def relative_std(self) -> np.ndarray:
        """|σ / value| (nan where the value is 0 or σ unknown)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.abs(self.std / np.where(self.value != 0, self.value, np.nan))


def from_result(result: ResultDocument) -> Derivatives | None:
    """The table of an identification, or None when the model is not in output
    coordinates."""
    if result.Ac is None or result.Bc is None:
        return None
    refinement = result.refinement
    return from_matrices(
        result.outputs,
        result.inputs,
        result.Ac,
        result.Bc,
        None if refinement is None else refinement.Ac_std,
        None if refinement is None else refinement.Bc_std,
    )


def from_matrices(outputs, inputs, Ac, Bc, Ac_std=None, Bc_std=None) -> Derivatives:
    """The table of a continuous model in output coordinates: its first len(outputs) states
    are the outputs; any more (the engine's lag states) are x5, x6, …"""
    Ac, Bc = np.asarray(Ac, dtype=float), np.asarray(Bc, dtype=float)
    m, n = len(outputs), Ac.shape[0]
    value = np.hstack([Ac, Bc])[:m]
    if Ac_std is None or Bc_std is None or not np.size(Ac_std):
        std = np.full(value.shape, np.nan)
    else:
        std = np.hstack([np.asarray(Ac_std, dtype=float), np.asarray(Bc_std, dtype=float)])[:m]
    states = [*outputs, *(f"x{k + 1}" for k in range(m, n))]
    return Derivatives(tuple(outputs), (*states, *inputs), value, std)


def to_csv(tables: Sequence[tuple[str, Derivatives]]) -> str:
    """One line per derivative: model, equation (the output whose rate), variable, value,
    standard error (empty: unknown; 0: fixed), and the standard error in % of the value."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["model", "equation", "variable", "value", "std", "std_percent"])
    for model_id, d in tables:
        relative = d.relative_std()
        for i, eq in enumerate(d.equations):
            for j, var in enumerate(d.variables):
                writer.writerow(
                    [
                        model_id,
                        f"d{eq}/dt",
                        var,
                        f"{d.value[i, j]:.6g}",
                        "" if np.isnan(d.std[i, j]) else f"{d.std[i, j]:.3g}",
                        "" if np.isnan(relative[i, j]) else f"{100 * relative[i, j]:.3g}",
                    ]
                )
    return out.getvalue()


def to_html(d: Derivatives) -> str:
    """The table as HTML: value ± σ (σ in % of the value beneath); fixed entries in grey,
    poorly determined ones (σ over POOR of the value) marked."""
    relative = d.relative_std()
    head = "<tr><th></th>" + "".join(f"<th>{html.escape(v)}</th>" for v in d.variables) + "</tr>"
    rows = []
    for i, eq in enumerate(d.equations):
        cells = [f"<th>d{html.escape(eq)}/dt</th>"]
        for j in range(len(d.variables)):
            value, std = d.value[i, j], d.std[i, j]
            if std == 0:
                cells.append(f'<td class="fixed">{value:.4g}</td>')
            elif np.isnan(std):
                cells.append(f"<td>{value:.4g}</td>")
            else:
                poor = ' class="poor"' if relative[i, j] > POOR else ""
                share = "" if np.isnan(relative[i, j]) else f"{100 * relative[i, j]:.0f} %"
                cells.append(f"<td{poor}>{value:.4g} ± {std:.2g}<br><small>{share}</small></td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f'<table class="derivatives">{head}{"".join(rows)}</table>'
