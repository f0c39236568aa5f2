"""What more than one tab of the console draws: numbers, mode rows, the yes-or-no dialog."""

from __future__ import annotations

from typing import ClassVar

from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Label

from agent.ident.document import ModeDocument

MODE_COLUMNS = ("mode", "eigenvalue", "f Hz", "ζ", "τ s", "MSV", "MCI", "MOI", "EMAC", "MPC", "CMI")


def num(value: float | None, fmt: str = "{:.2f}") -> str:
    """A number, or "–" for none."""
    return "–" if value is None else fmt.format(value)


def percent(value: float | None) -> str:
    """A percentage (MSV, MCI, MOI run 0–100): whole numbers from 10, two digits below, never
    an exponent (100 printed as "1e+02" read as a fault)."""
    if value is None:
        return "–"
    if abs(value) >= 9.95:
        return f"{value:.0f}"
    return f"{value:.2g}" if abs(value) >= 0.01 or value == 0 else "<0.01"


def mode_row(m: ModeDocument) -> tuple[str, ...]:
    """A mode as a row under MODE_COLUMNS."""
    lam = f"{m.real:+.3f}{m.imag:+.3f}j" if m.imag else f"{m.real:+.3f}"
    return (
        m.name or "–",
        lam,
        num(m.frequency_hz, "{:.3f}"),
        num(m.damping),
        num(m.time_constant_s, "{:.2f}"),
        percent(m.msv),
        percent(m.mci),
        percent(m.moi),
        num(m.emac, "{:.0f}"),
        num(m.mpc, "{:.0f}"),
        num(m.cmi, "{:.0f}"),
    )


def mode_line(m: ModeDocument) -> str:
    """A mode's row as one line: name, eigenvalue with its σ, ωn, ζ with its σ, τ."""
    lam = f"{m.real:+.3f}{m.imag:+.3f}j" if m.imag else f"{m.real:+.3f}"
    if m.real_std is not None and m.imag_std is not None:
        lam += f" (σ {m.real_std:.2g}, {m.imag_std:.2g})" if m.imag else f" (σ {m.real_std:.2g})"
    parts = [f"{m.name or 'unnamed'}: λ {lam}"]
    if m.frequency_hz is not None:
        parts.append(f"f {m.frequency_hz:.3g} Hz")
    if m.imag and m.damping is not None:
        zeta = f"ζ {m.damping:.3f}"
        if m.damping_std is not None:
            zeta += f" ± {m.damping_std:.2g}"
        parts.append(zeta)
    if m.time_constant_s is not None:
        parts.append(f"τ {m.time_constant_s:.3g} s")
    return "; ".join(parts)


class Confirm(ModalScreen[bool]):
    """Yes or no, on one key."""

    BINDINGS: ClassVar = [
        ("y", "answer(True)", "yes"),
        ("n", "answer(False)", "no"),
        ("escape", "answer(False)", "no"),
    ]

    def __init__(self, question: str):
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.question)
            with Horizontal():
                yield Button("Yes (y)", id="yes", variant="warning")
                yield Button("No (n)", id="no")

    def action_answer(self, answer: bool) -> None:
        self.dismiss(answer)

    @on(Button.Pressed)
    def _pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")
