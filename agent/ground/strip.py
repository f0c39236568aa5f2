"""A strip chart in a terminal: one or two traces of (time, value) over the last seconds,
drawn as lines in braille dots (two across and four down per cell), each in its colour (a cell
both cross is drawn in white), on a scale fitted to what is shown."""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text
from textual.widget import Widget

# Braille dot bits by (column, row) within a cell.
DOTS = ((0x01, 0x02, 0x04, 0x40), (0x08, 0x10, 0x20, 0x80))
BOTH = "bold white"

Trace = tuple[Sequence[tuple[float, float | None]], str]  # the samples, the colour


def draw(traces: Sequence[Trace], width: int, height: int, span: float) -> Text:
    """The traces' last `span` seconds across `width` cells, `height` cells high."""
    width, height = max(width, 4), max(height, 1)
    w, h = 2 * width, 4 * height
    times = [t for samples, _ in traces for t, v in samples if v is not None]
    values = [v for samples, _ in traces for _, v in samples if v is not None]
    cells: list[list[tuple[int, set[str]]]] = [
        [(0, set()) for _ in range(width)] for _ in range(height)
    ]
    if values:
        end = max(times)
        lo, hi = min(values), max(values)
        if hi - lo < 1e-9:
            lo, hi = lo - 1.0, hi + 1.0
        pad = 0.08 * (hi - lo)
        lo, hi = lo - pad, hi + pad

        def dot(t: float, v: float) -> tuple[int, int]:
            x = round((t - (end - span)) / span * (w - 1))
            y = round((hi - v) / (hi - lo) * (h - 1))
            return x, y

        for samples, colour in traces:
            points = [dot(t, v) for t, v in samples if v is not None and t >= end - span]
            for (x0, y0), (x1, y1) in zip(points, points[1:] or points, strict=False):
                steps = max(abs(x1 - x0), abs(y1 - y0), 1)
                for k in range(steps + 1):
                    x = round(x0 + (x1 - x0) * k / steps)
                    y = round(y0 + (y1 - y0) * k / steps)
                    if 0 <= x < w and 0 <= y < h:
                        bits, colours = cells[y // 4][x // 2]
                        cells[y // 4][x // 2] = (bits | DOTS[x % 2][y % 4], colours | {colour})
    text = Text()
    for r, line in enumerate(cells):
        for bits, colours in line:
            style = BOTH if len(colours) > 1 else next(iter(colours), "")
            text.append(chr(0x2800 + bits) if bits else " ", style)
        if r < height - 1:
            text.append("\n")
    return text


class Strip(Widget):
    """One strip chart (`draw`) of the traces given to `show`."""

    DEFAULT_CSS = "Strip { height: 2; }"

    def __init__(self, span: float, **kwargs):
        super().__init__(**kwargs)
        self.span = span
        self.traces: list[Trace] = []

    def show(self, traces: list[Trace]) -> None:
        self.traces = traces
        self.refresh()

    def render(self) -> Text:
        return draw(self.traces, self.size.width, self.size.height, self.span)


def scale_of(traces: Sequence[Trace]) -> tuple[float, float] | None:
    """The values' range over the traces (None: no value)."""
    values = [v for samples, _ in traces for _, v in samples if v is not None]
    return (min(values), max(values)) if values else None
