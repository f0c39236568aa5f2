"""The s-plane in a terminal: every identified eigenvalue of the flight (thesis figure 6.5),
the nominal model's highlighted, the selected candidate's marked."""

from __future__ import annotations

from dataclasses import dataclass

from rich.text import Text
from textual.widget import Widget

MARKS = {
    "history": ("·", "grey50"),
    "candidate": ("◆", "bold yellow"),
    "nominal": ("●", "bold green"),
}
# Drawn last wins: the nominal and the selected candidate stay visible over the history.
ORDER = ("history", "candidate", "nominal")


@dataclass(frozen=True)
class Point:
    value: complex
    kind: str  # history, candidate, nominal


def grid(points: list[Point], width: int, height: int) -> Text:
    """Real part across, imaginary part up; the axes through the origin."""
    width, height = max(width, 20), max(height, 5)
    plot_w, plot_h = width - 8, height - 2  # room for the labels
    values = [p.value for p in points] or [complex(-1, 1)]
    re_min = min(min(v.real for v in values), 0.0)
    re_max = max(max(v.real for v in values), 0.0)
    im_max = max(max(abs(v.imag) for v in values), 0.1)
    span = (re_max - re_min) or 1.0
    re_min, re_max = re_min - 0.05 * span, re_max + 0.05 * span
    cells: list[list[tuple[str, str]]] = [[(" ", "")] * plot_w for _ in range(plot_h)]

    def col(x: float) -> int:
        return min(plot_w - 1, max(0, round((x - re_min) / (re_max - re_min) * (plot_w - 1))))

    def row(y: float) -> int:
        return min(plot_h - 1, max(0, round((im_max - y) / (2 * im_max) * (plot_h - 1))))

    zero_c, zero_r = col(0.0), row(0.0)
    for r in range(plot_h):
        cells[r][zero_c] = ("│", "grey35")
    for c in range(plot_w):
        cells[zero_r][c] = ("┼" if c == zero_c else "─", "grey35")
    for kind in ORDER:
        mark, style = MARKS[kind]
        for p in points:
            if p.kind == kind:
                cells[row(p.value.imag)][col(p.value.real)] = (mark, style)
    text = Text()
    for r, line in enumerate(cells):
        label = f"{im_max:+6.1f} " if r == 0 else f"{-im_max:+6.1f} " if r == plot_h - 1 else ""
        text.append(f"{label:>8}")
        for char, style in line:
            text.append(char, style)
        text.append("\n")
    left, right = f"{re_min:.1f}", f"{re_max:.1f}"
    text.append(" " * 8 + left + " " * max(1, plot_w - len(left) - len(right)) + right + "\n")
    legend = "  ".join(f"{MARKS[k][0]} {k}" for k in ("nominal", "candidate", "history"))
    text.append(" " * 8 + f"Re (1/s) across, Im (rad/s) up   {legend}", "grey70")
    return text


class SPlane(Widget):
    """Eigenvalues accumulating over the flight."""

    DEFAULT_CSS = "SPlane { height: 14; min-width: 30; }"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.points: list[Point] = []

    def show(self, points: list[Point]) -> None:
        self.points = points
        self.refresh()

    def render(self) -> Text:
        return grid(self.points, self.size.width, self.size.height - 1)
