"""The report's s-plane: an inline SVG, so each mode answers hover (its row as a tooltip) and
a click (the page scrolls to its row in the mode table).

Drawn on `agent.splane`'s log-radius plane, with its ζ rays and ωn circles. Each mode of the
model in question is a cross in its own colour with its name and its Cramér–Rao 2σ ellipse;
the nominal model's modes are open diamonds with theirs (dashed); earlier identifications are
faded grey crosses, so the plane tells where this model sits against what came before. The
right half plane (unstable) is shaded.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent import splane
from agent.ident.document import ModeDocument

COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2")
SIGMAS = 2.0


@dataclass(frozen=True)
class Mark:
    """One mode: the eigenvalue with Im ≥ 0 (its conjugate is drawn too)."""

    s: complex
    std: tuple[float, float] | None  # Cramér–Rao 1-σ of Re and Im (None: unknown)
    name: str | None
    kind: str  # "this", "nominal" or "earlier"
    tooltip: str
    href: str | None = None  # the mode's row
    colour: str = COLOURS[0]


def marks_of(
    modes: Sequence[ModeDocument], kind: str, label: str, anchor: str | None = None
) -> list[Mark]:
    """Marks of a result's modes; `anchor`: the id prefix of their rows in the mode table
    (row k is `{anchor}-{k}`)."""
    return [
        Mark(
            s=complex(*m.eigenvalue),
            std=m.eigenvalue_std,
            name=m.name,
            kind=kind,
            tooltip=f"{label}: {tooltip(m)}",
            href=None if anchor is None else f"#{anchor}-{k}",
            colour=COLOURS[k % len(COLOURS)],
        )
        for k, m in enumerate(modes)
    ]


def tooltip(m: ModeDocument) -> str:
    """A mode's row as one line."""
    re, im = m.eigenvalue
    lam = f"{re:+.3f} ± {abs(im):.3f}j" if im else f"{re:+.3f}"
    std = m.eigenvalue_std
    if std is not None:
        lam += f" (σ {std[0]:.2g}, {std[1]:.2g})" if im else f" (σ {std[0]:.2g})"
    parts = [f"{m.name or 'unnamed'}: λ {lam} 1/s"]
    omega = m.frequency_rad_s
    if omega:
        parts.append(f"ωn {omega:.3g} rad/s ({m.frequency_hz:.3g} Hz)")
    if im:
        zeta = f"ζ {m.damping:.3f}"
        if m.damping_std is not None:
            zeta += f" ± {m.damping_std:.2g}"
        parts.append(zeta)
    if m.time_constant_s is not None:
        parts.append(f"τ {m.time_constant_s:.3g} s")
    return "; ".join(parts)


def svg(marks: Sequence[Mark], title: str, width: int = 620, height: int = 440) -> str:
    """The plane with its grid and the marks, as an <svg> element."""
    points = [splane.warp(m.s) for m in marks]
    for m in marks:
        if m.std is not None:
            points.extend(splane.warp(splane.ellipse(m.s, m.std, SIGMAS)))
    drawn = np.concatenate([np.atleast_1d(p) for p in points]) if points else np.zeros(1)
    radius = max(float(np.abs(drawn).max()), splane.warped_radius(1.0)) * 1.08
    right = max(0.25 * radius, float(drawn.real.max()) * 1.1)
    pad, foot = 34, 58
    scale = min((width - 2 * pad) / (radius + right), (height - pad - foot) / (2 * radius))
    width = max(round((radius + right) * scale + 2 * pad), 480)  # the legend's room at least
    cx = pad + radius * scale
    cy = pad + radius * scale

    def xy(z) -> tuple[float, float]:
        return cx + z.real * scale, cy - z.imag * scale

    out = [
        f'<svg class="splane" xmlns="http://www.w3.org/2000/svg" width="{width}" '
        f'height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" '
        'font-size="11">',
        f"<title>{html.escape(title)}</title>",
        '<defs><clipPath id="plane"><rect x="0" y="0" '
        f'width="{width}" height="{height - foot + 8}"/></clipPath></defs>',
        f'<rect x="{cx:.1f}" y="{pad - 10}" width="{right * scale + 10:.1f}" '
        f'height="{2 * radius * scale + 20:.1f}" fill="#fbecec"/>',
        '<g clip-path="url(#plane)" stroke="#bbb" fill="none" stroke-width="0.8">',
    ]
    for omega in splane.OMEGA_GRID:
        r = splane.warped_radius(omega) * scale
        if r > radius * scale:
            continue
        out.append(
            f'<circle class="omega" cx="{cx:.1f}" cy="{cy:.1f}" r="{r:.1f}" '
            'stroke-dasharray="3 3"/>'
        )
        out.append(
            f'<text x="{cx - 3:.1f}" y="{cy - r - 3:.1f}" fill="#888" stroke="none" '
            f'text-anchor="end">ωn {omega:g}</text>'
        )
    for n, zeta in enumerate(splane.ZETA_GRID):
        for upper in (True, False):
            x, y = xy(splane.zeta_ray(zeta, radius, upper))  # the angle is kept: same ray
            out.append(
                f'<line class="zeta" x1="{cx:.1f}" y1="{cy:.1f}" x2="{x:.1f}" y2="{y:.1f}"/>'
            )
        # Labelled in the lower half, staggered so the near-vertical rays' labels do not meet.
        x, y = xy(splane.zeta_ray(zeta, radius * (0.96 - 0.1 * (n % 2)), False))
        out.append(
            f'<text x="{x - 3:.1f}" y="{y + 4:.1f}" fill="#888" stroke="none" '
            f'text-anchor="end">ζ {zeta:g}</text>'
        )
    out.append(
        f'<line x1="{pad / 2:.1f}" y1="{cy:.1f}" x2="{cx + right * scale:.1f}" y2="{cy:.1f}" '
        'stroke="#666"/>'
        f'<line x1="{cx:.1f}" y1="{pad - 10}" x2="{cx:.1f}" y2="{cy + radius * scale + 10:.1f}" '
        'stroke="#666"/></g>'
    )
    order = {"earlier": 0, "nominal": 1, "this": 2}
    for m in sorted(marks, key=lambda m: order[m.kind]):
        out.append(_mark(m, xy))
    legend = (
        f"× this model, with its {SIGMAS:g}σ Cramér–Rao ellipse   ◇ nominal   faded ×: earlier",
        "shaded: unstable   radius on a log scale: ζ rays and ωn circles keep their shape",
        "Re (1/s) across, Im (rad/s) up; hover a mode for its row, click to go to it",
    )
    for k, line in enumerate(legend):
        y = height - foot + 16 + 14 * k
        out.append(f'<text x="{pad / 2}" y="{y}" fill="#555">{html.escape(line)}</text>')
    out.append("</svg>")
    return "".join(out)


def _mark(m: Mark, xy) -> str:
    style = {
        "this": (m.colour, 1.0, 2.0),
        "nominal": ("#000", 1.0, 1.6),
        "earlier": ("#888", 0.45, 1.0),
    }[m.kind]
    colour, opacity, width = style
    parts = [
        f'<g class="mode {m.kind}" opacity="{opacity}"><title>{html.escape(m.tooltip)}</title>'
    ]
    if m.std is not None and m.kind != "earlier":
        ring = [xy(z) for z in splane.warp(splane.ellipse(m.s, m.std, SIGMAS))]
        dash = ' stroke-dasharray="4 2"' if m.kind == "nominal" else ""
        for sign in (1, -1) if m.s.imag else (1,):
            pts = " ".join(f"{x:.1f},{_mirror(y, xy, sign):.1f}" for x, y in ring)
            parts.append(
                f'<polygon class="ellipse" points="{pts}" fill="{colour}" fill-opacity="0.08" '
                f'stroke="{colour}" stroke-width="1"{dash}/>'
            )
    for s in (m.s, m.s.conjugate()) if m.s.imag else (m.s,):
        x, y = xy(splane.warp(s))
        if m.kind == "nominal":
            parts.append(
                f'<path d="M{x:.1f},{y - 7:.1f} l7,7 l-7,7 l-7,-7 z" fill="none" '
                f'stroke="{colour}" stroke-width="{width}"/>'
            )
        else:
            size = 5 if m.kind == "this" else 3.5
            parts.append(
                f'<path d="M{x - size:.1f},{y - size:.1f} l{2 * size},{2 * size} '
                f'm0,{-2 * size} l{-2 * size},{2 * size}" stroke="{colour}" '
                f'stroke-width="{width}"/>'
            )
    if m.kind == "this" and m.name:
        x, y = xy(splane.warp(m.s))
        parts.append(
            f'<text x="{x + 7:.1f}" y="{y - 7:.1f}" fill="{colour}">{html.escape(m.name)}</text>'
        )
    parts.append("</g>")
    body = "".join(parts)
    return f'<a href="{m.href}">{body}</a>' if m.href else body


def _mirror(y: float, xy, sign: int) -> float:
    """A drawn y, mirrored about the real axis for the conjugate (sign −1)."""
    _, cy = xy(0j)
    return y if sign == 1 else 2 * cy - y
