"""`sysid excite`: a plan before flight, as CSV, a JSON summary or a plot."""

from __future__ import annotations

import io
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from agent.excitation.plan import Plan, Timeline
from agent.outputs import Outputs

# The largest plan file read: a plan is a few kilobytes of JSON; anything longer (a flight
# log given by mistake, /dev/zero) is refused at this length, not read whole.
MAX_PLAN_BYTES = 1 << 20


class PreviewError(ValueError):
    """The plan file cannot be read or is not a valid plan."""


def load_plan(path: Path) -> Plan:
    """A plan from a JSON file (the same JSON the radio carries), at most MAX_PLAN_BYTES."""
    try:
        with path.open("rb") as handle:
            data = handle.read(MAX_PLAN_BYTES + 1)
        if len(data) > MAX_PLAN_BYTES:
            raise PreviewError(
                f"{path}: longer than {MAX_PLAN_BYTES} bytes; not a plan (a plan is a few "
                "kilobytes of JSON)"
            )
        return Plan.from_bytes(data)
    except OSError as exc:
        raise PreviewError(f"{path}: cannot be read: {exc.strerror or exc}") from exc
    except ValidationError as exc:
        errors = exc.errors()
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc']) or '(top level)'}: {e['msg']}"
            for e in errors
            if not _echo(e, errors)
        )
        raise PreviewError(f"{path}: not a valid plan: {problems}") from exc


def _echo(error, errors) -> bool:
    """pydantic's "Tuple should have at least 1 item after validation" for a tuple whose item
    was refused: an echo of that item's error, which is the one to read."""
    loc = error["loc"]
    return error["type"] == "too_short" and any(
        e["loc"][: len(loc)] == loc and len(e["loc"]) > len(loc) for e in errors
    )


def parse_amplitudes(items: list[str]) -> dict[str, float]:
    """CONTROL=VALUE pairs from the command line; VALUE finite and not 0."""
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            amplitude = float(value)
        except ValueError:
            sep = ""
        if not sep:
            raise PreviewError(f"--amplitude wants CONTROL=VALUE, got {item!r}")
        if not math.isfinite(amplitude) or amplitude == 0:
            raise PreviewError(
                f"--amplitude {item}: give a finite amplitude other than 0, in degrees from "
                "trim (throttle: percent); a negative one reverses the signal"
            )
        out[name.strip()] = amplitude
    return out


def csv_text(timeline: Timeline, columns: Mapping[str, str]) -> str:
    """Header `time,<column per control>`, then one row per command (units from trim)."""
    names = list(timeline.values)
    out = io.StringIO()
    out.write(",".join(["time"] + [columns[n] for n in names]) + "\n")
    data = np.column_stack([timeline.times()] + [timeline.values[n] for n in names])
    np.savetxt(out, data, delimiter=",", fmt="%.6g")
    return out.getvalue()


def plot(
    timeline: Timeline,
    summary: dict,
    columns: Mapping[str, str],
    path: Path,
    outputs: Outputs | None = None,
) -> None:
    """One panel per control, deflection from trim against time, RPF and peak in the title;
    written through `outputs` (the command's, which checked `path` against its inputs)."""
    import matplotlib

    matplotlib.use("Agg")  # files only: no display onboard or in CI
    import matplotlib.pyplot as plt

    names = list(timeline.values)
    fig, axes = plt.subplots(len(names), 1, sharex=True, figsize=(9, 1.8 * len(names) + 0.8))
    axes = np.atleast_1d(axes)
    t = timeline.times()
    for ax, name in zip(axes, names, strict=True):
        info = summary["controls"][name]
        ax.plot(t, timeline.values[name], lw=0.9)
        ax.set_ylabel(f"{columns[name]}\n[{info['unit'] or '?'}]")
        ax.set_title(f"RPF {info['rpf']:.2f}, peak {info['peak']:.3g}", fontsize=8, loc="right")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time from start [s]")
    fig.suptitle(f"plan {timeline.plan.id} ({timeline.plan.axes}), {1 / timeline.dt:g} Hz")
    fig.tight_layout()
    try:
        with (outputs or Outputs({})).open(path) as handle:
            fig.savefig(handle, dpi=100, format=path.suffix[1:] or None)
    except OSError as exc:
        raise PreviewError(f"{path}: cannot be written: {exc.strerror or exc}") from exc
    finally:
        plt.close(fig)
