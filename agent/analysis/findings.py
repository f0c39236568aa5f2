"""What `sysid analyze` found in its cases' outcomes (`agent.analysis.analyze`): the sweep's
table in the thesis's table-6.6 view — per setting the mean TIC_avg and how consistently each
named mode comes out across the excitations — with a recommended setting, the cross-validation
matrix (each model's TIC on every excitation: the thesis's TIC_jN), and the report of it all
as the `--json` object (each case with its identification's document) or as text.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agent.analysis.analyze import Case
from agent.ident import job as jobs
from agent.ident.document import ResultDocument
from agent.ident.errors import DataError
from agent.ident.job import Outcome

# A setting is "within" the best if its mean TIC_avg is at most this much worse (relative).
TIC_MARGIN = 0.10
# Named modes agree across excitations if their eigenvalues are within this (relative).
CONSISTENT = 0.15


def named_modes(outcome: Outcome) -> dict[str, complex]:
    """The named modes of a case's model by name (none when it failed)."""
    if not outcome.ok:
        return {}
    return {m.name: complex(*m.eigenvalue) for m in outcome.result.modes if m.name}


@dataclass(frozen=True, kw_only=True)
class SweepRow:
    """One swept value (thesis table 6.6): what the excitations gave with it."""

    setting: dict[str, int]
    identified: int  # excitations identified
    failed: list[str]  # why the others were not
    tic_avg: float | None  # mean TIC_avg over the identified (None: none was)
    orders: list[int]
    markov: list[int]  # OKID's p (none for the whole-aircraft method)
    modes: dict[str, list[list[float]]]  # each mode named in every excitation: [re, im] each
    spread: dict[str, float]  # each such mode's worst relative deviation from its median

    def consistent(self) -> int:
        """How many named modes agree across the excitations (spread < CONSISTENT)."""
        return sum(s < CONSISTENT for s in self.spread.values())


def sweep_table(cases: Sequence[Case], outcomes: Sequence[Outcome]) -> list[SweepRow]:
    """One row per swept value: mean TIC_avg over the excitations, the modes named in every
    excitation, and each mode's worst relative deviation from its median across them. With
    one excitation the spread is instead each mode's deviation from its median over the whole
    sweep: how settled the mode is as the setting changes."""
    rows: dict[tuple, list[Outcome]] = {}
    for case, outcome in zip(cases, outcomes, strict=True):
        rows.setdefault(case.key, []).append(outcome)
    single = all(len(g) == 1 for g in rows.values())
    table = []
    for key, group in rows.items():
        ok = [o.result for o in group if o.ok]
        modes = [named_modes(o) for o in group if o.ok]
        common = sorted(set.intersection(*(set(m) for m in modes))) if modes else []
        spread = {}
        for name in common:
            values = np.array([m[name] for m in modes])
            centre = complex(np.median(values.real), np.median(np.abs(values.imag)))
            values = values.real + 1j * np.abs(values.imag)
            spread[name] = float(np.max(np.abs(values - centre)) / max(abs(centre), 1e-9))
        table.append(
            SweepRow(
                setting=dict(key),
                identified=len(ok),
                failed=[o.reason for o in group if not o.ok],
                tic_avg=float(np.mean([r.tic_avg for r in ok])) if ok else None,
                orders=sorted({r.order for r in ok}),
                markov=sorted({r.okid.markov for r in ok if r.okid is not None}),
                modes={n: [[m[n].real, m[n].imag] for m in modes] for n in common},
                spread=spread,
            )
        )
    if single and len(table) > 1:
        _spread_over_sweep(table)
    return table


def _spread_over_sweep(table: list[SweepRow]) -> None:
    names = set.intersection(*(set(r.modes) for r in table if r.modes)) if table else set()
    for name in names:
        values = np.array([complex(*row.modes[name][0]) for row in table if row.modes])
        values = values.real + 1j * np.abs(values.imag)
        centre = complex(np.median(values.real), np.median(values.imag))
        for row in table:
            if name in row.modes:
                lam = complex(*row.modes[name][0])
                lam = complex(lam.real, abs(lam.imag))
                row.spread[name] = abs(lam - centre) / max(abs(centre), 1e-9)


def recommend(table: Sequence[SweepRow], excitations: int) -> SweepRow | None:
    """The first setting (smallest value) whose TIC_avg is within TIC_MARGIN of the best,
    identified every excitation, and names the most modes consistently (spread < CONSISTENT);
    None when nothing identified."""
    usable = [r for r in table if r.tic_avg is not None and r.identified == excitations]
    if not usable:
        return None
    best = min(r.tic_avg for r in usable)
    near = [r for r in usable if r.tic_avg <= best * (1 + TIC_MARGIN)]
    most = max(r.consistent() for r in near)
    return next(r for r in near if r.consistent() == most)


def cross_validation(
    cases: Sequence[Case], outcomes: Sequence[Outcome]
) -> list[list[float | None]]:
    """TIC_avg of the model of excitation i on excitation j's data (rows i, columns j); the
    diagonal is each model on its own data."""
    matrix: list[list[float | None]] = []
    for case, outcome in zip(cases, outcomes, strict=True):
        row: list[float | None] = []
        for other in cases:
            if not outcome.ok:
                row.append(None)
                continue
            channels = (other.job.inputs, other.job.outputs)
            try:
                row.append(
                    jobs.cross_tic(
                        outcome.result, case.job.record_dt, other.job.experiments, channels
                    )
                )
            except DataError:  # a model of channels that excitation's record did not move
                row.append(None)
        matrix.append(row)
    return matrix


@dataclass(frozen=True, kw_only=True)
class Analysis:
    """What `sysid analyze` found: each case's outcome; with a sweep, its table and the
    recommended setting; with cross-validation, each model's TIC on every excitation."""

    logs: tuple[Path, ...]
    cases: tuple[Case, ...]
    outcomes: tuple[Outcome, ...]
    sweep: list[SweepRow] | None = None
    recommended: SweepRow | None = None
    cross_tic: list[list[float | None]] | None = None

    def document(self) -> dict[str, Any]:
        """`sysid analyze --json`'s object: the logs, each case with its identification's
        document (`result`) or why it failed, the sweep's table and recommendation, the
        cross-validation matrix."""
        report: dict[str, Any] = {
            "logs": [str(p) for p in self.logs],
            "cases": [case_document(c, o) for c, o in zip(self.cases, self.outcomes, strict=True)],
        }
        if self.sweep is not None:
            report["sweep"] = [asdict(row) for row in self.sweep]
            report["recommended"] = None if self.recommended is None else asdict(self.recommended)
        if self.cross_tic is not None:
            report["cross_tic"] = self.cross_tic
        return report

    def text(self) -> str:
        """The report as text: each case, the sweep table, the cross-validation."""
        lines = [f"{len(self.logs)} log(s): " + ", ".join(Path(p).name for p in self.logs)]
        lines += [_case_line(c, o) for c, o in zip(self.cases, self.outcomes, strict=True)]
        if self.sweep is not None:
            lines += ["", *_sweep_lines(self.sweep, self.recommended)]
        if self.cross_tic is not None:
            lines.append("")
            lines.append("TIC_avg of model i (rows) on excitation j (columns):")
            for k, row in enumerate(self.cross_tic, start=1):
                cells = " ".join("    –" if v is None else f"{v:5.3f}" for v in row)
                lines.append(f"  {k:>2}: {cells}")
        return "\n".join(lines)


def analysed(
    logs: Sequence[Path],
    cases: Sequence[Case],
    outcomes: Sequence[Outcome],
    *,
    excitations: int,
    sweep: bool = False,
    cross: bool = False,
) -> Analysis:
    """The analysis of the cases' outcomes: with `sweep` the table and the setting
    recommended for `excitations` excitations, with `cross` the cross-validation."""
    table = sweep_table(cases, outcomes) if sweep else None
    return Analysis(
        logs=tuple(logs),
        cases=tuple(cases),
        outcomes=tuple(outcomes),
        sweep=table,
        recommended=None if table is None else recommend(table, excitations),
        cross_tic=cross_validation(cases, outcomes) if cross else None,
    )


def case_document(case: Case, outcome: Outcome) -> dict[str, Any]:
    """One case in `sysid analyze --json`: which excitation and setting, and the
    identification's document, or why there is none."""
    head: dict[str, Any] = {"excitation": case.label, "setting": dict(case.key), "ok": outcome.ok}
    if not outcome.ok:
        return head | {"reason": outcome.reason}
    return head | {"result": outcome.result.model_dump(mode="json")}


def structure(result: ResultDocument) -> str:
    """The model's structure in a few words: OKID's p and the order, or the method's name."""
    if result.okid is not None:
        return f"p {result.okid.markov}, n {result.order}"
    return f"{result.method} method, n {result.order}"


def _case_line(case: Case, outcome: Outcome) -> str:
    setting = " ".join(f"{k}={v}" for k, v in case.key)
    head = f"excitation {case.label}" + (f" ({setting})" if setting else "")
    if not outcome.ok:
        return f"{head}: failed: {outcome.reason}"
    r = outcome.result
    modes = ", ".join(f"{m.name} {complex(*m.eigenvalue):.3f}" for m in r.modes if m.name)
    return f"{head}: {structure(r)}, TIC_avg {r.tic_avg:.3f}; {modes or 'no named mode'}"


def _sweep_lines(table: Sequence[SweepRow], best: SweepRow | None) -> list[str]:
    lines = [f"{'setting':<14}{'TIC_avg':>9}  {'ok':>3}  modes (worst spread across excitations)"]
    for row in table:
        setting = " ".join(f"{k}={v}" for k, v in row.setting.items())
        tic = "–" if row.tic_avg is None else f"{row.tic_avg:.4f}"
        spread = ", ".join(f"{n} {100 * s:.0f}%" for n, s in row.spread.items())
        lines.append(f"{setting:<14}{tic:>9}  {row.identified:>3}  {spread or '–'}")
    chosen = " ".join(f"{k}={v}" for k, v in best.setting.items()) if best else None
    lines.append(f"recommended: {chosen or 'none (nothing identified every time)'}")
    return lines
