"""The s-plane in a terminal: the selected result's modes with their Cramér–Rao 2σ ellipses
and names, the nominal model's, and every earlier identification of the flight faded (thesis
figure 6.5), over ζ rays and ωn circles. The radius is on `agent.splane`'s log scale, so a
0.01 rad/s spiral and a 12 rad/s roll both show. The upper half plane only (a pair's other
pole is its mirror image), stretched across the width: the ζ rays stay straight and the ωn
circles become ellipses, drawn in the same stretch, so a mode's ζ and ωn read off the grid.
The mode picked in the mode table is drawn in reverse and its row printed beneath."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rich.text import Text
from textual.widget import Widget

from agent import splane

MARKS = {
    "history": ("∙", "grey58"),
    "nominal": ("◇", "bold green"),
    "candidate": ("✕", "bold yellow"),
}
# Drawn last wins: the nominal and the candidate stay visible over the history.
ORDER = ("history", "nominal", "candidate")
GRID_STYLE = "grey27"
# A terminal cell is about twice as high as it is wide; the plane may be stretched across up
# to this much more to use the width.
CELL_ASPECT = 2.0
STRETCH_MAX = 2.5
SIGMAS = 2.0


@dataclass(frozen=True)
class Point:
    value: complex
    kind: str  # history, candidate, nominal
    name: str | None = None
    std: tuple[float, float] | None = None  # Cramér–Rao 1-σ of Re and Im
    row: str = ""  # the mode's row, printed when it is the selected one
    index: int | None = None  # its row in the mode table (candidate's modes)


def grid(points: list[Point], width: int, height: int, selected: int | None = None) -> Text:
    """The plane in width × height cells (the last three lines: scale, legend, selection)."""
    width, height = max(width, 24), max(height, 8)
    plot_w, plot_h = width - 1, height - 3
    drawn = [splane.warp(p.value) for p in points] or [splane.warp(-1 + 1j)]
    for p in points:
        if p.std is not None and p.kind != "history":
            drawn.extend(splane.warp(splane.ellipse(p.value, p.std, SIGMAS)))
    drawn = np.asarray(drawn)
    radius = max(float(np.abs(drawn).max()), splane.warped_radius(1.0)) * 1.1
    right = max(0.25 * radius, float(drawn.real.max()) * 1.1)
    # The rows span Im 0 to the radius; the columns Re −radius to `right`.
    scale_y = (plot_h - 1) / radius
    scale_x = min(scale_y * CELL_ASPECT * STRETCH_MAX, (plot_w - 1) / (radius + right))
    cells: list[list[tuple[str, str]]] = [[(" ", "")] * plot_w for _ in range(plot_h)]

    def cell(z: complex) -> tuple[int, int] | None:
        c = round((z.real + radius) * scale_x)
        r = round((radius - z.imag) * scale_y)
        return (r, c) if 0 <= r < plot_h and 0 <= c < plot_w else None

    def put(z: complex, char: str, style: str, over: bool = True) -> None:
        at = cell(z)
        if at is not None and (over or cells[at[0]][at[1]][0] == " "):
            cells[at[0]][at[1]] = (char, style)

    for omega in splane.OMEGA_GRID:
        r = splane.warped_radius(omega)
        if r < radius:
            for t in np.linspace(0, 2 * np.pi, 160):
                put(r * np.exp(1j * t), "·", GRID_STYLE)
    for zeta in splane.ZETA_GRID:
        end = splane.zeta_ray(zeta, radius)
        for f in np.linspace(0.05, 1.0, 80):
            put(f * end, "·", GRID_STYLE)
        at = cell(0.97 * end)  # its label at the top of the ray
        if at is not None:
            for k, ch in enumerate(f"{zeta:g}"):
                if at[1] + k < plot_w:
                    cells[at[0]][at[1] + k] = (ch, "grey42")
    origin = cell(0j)
    if origin is not None:
        for r in range(plot_h):
            cells[r][origin[1]] = ("│", "grey35")
        for c in range(plot_w):
            cells[origin[0]][c] = ("┼" if c == origin[1] else "─", "grey35")
    for omega in splane.OMEGA_GRID:  # ωn labels up the imaginary axis
        r = splane.warped_radius(omega)
        at = cell(complex(0, r))
        if r < radius and at is not None:
            label = f"{omega:g}"
            for k, ch in enumerate(label):
                if at[1] + 1 + k < plot_w:
                    cells[at[0]][at[1] + 1 + k] = (ch, "grey50")
    for kind in ORDER:
        mark, style = MARKS[kind]
        for p in (p for p in points if p.kind == kind):
            if p.std is not None and kind != "history":
                for z in splane.warp(splane.ellipse(p.value, p.std, SIGMAS)):
                    put(z, "∘", style.replace("bold ", ""), over=False)
            chosen = kind == "candidate" and p.index is not None and p.index == selected
            put(splane.warp(p.value), mark, f"{style} reverse" if chosen else style)
    for p in points:  # the candidate's names beside its upper-half marks
        if p.kind == "candidate" and p.name and p.value.imag >= 0:
            at = cell(splane.warp(p.value))
            if at is not None:
                for k, ch in enumerate(p.name):
                    c = at[1] + 2 + k
                    if c < plot_w and cells[at[0]][c][0] in " ·─│┼∘":
                        cells[at[0]][c] = (ch, "yellow")
    text = Text()
    for line in cells:
        for char, style in line:
            text.append(char, style)
        text.append("\n")
    legend = "  ".join(f"{MARKS[k][0]} {k}" for k in ("candidate", "nominal", "history"))
    text.append(f"{legend}  ∘ {SIGMAS:g}σ   ", "grey70")
    text.append("ωn rad/s on the axis, ζ at the rays, log radius\n", "grey50")
    row = next((p.row for p in points if p.kind == "candidate" and p.index == selected), "")
    text.append(row or "pick a mode in the table for its row", "bold" if row else "grey50")
    return text


class SPlane(Widget):
    """Eigenvalues accumulating over the flight."""

    DEFAULT_CSS = "SPlane { height: 18; min-width: 30; }"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.points: list[Point] = []
        self.selected: int | None = None

    def show(self, points: list[Point]) -> None:
        self.points = points
        self.refresh()

    def select(self, index: int | None) -> None:
        """Pick the candidate's mode `index` (its row in the mode table)."""
        self.selected = index
        self.refresh()

    def render(self) -> Text:
        return grid(self.points, self.size.width, self.size.height, self.selected)
