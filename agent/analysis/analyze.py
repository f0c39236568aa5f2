"""`sysid analyze`: the onboard identification re-run on the logs with changed settings
(thesis 6.2.3) — per excitation or as one batch, or once per value of a sweep of p or the
order. This module makes and runs the cases; `findings` tabulates what they found (the sweep's
table and recommendation, the cross-validation) and reports it.

Each identification is the agent's own worker job (`agent.ident.job.run`), so the numbers are
the ones the aircraft would have produced. Jobs run in parallel processes (`jobs`), or on a
Dask cluster (`scheduler`, a `dask.distributed` address).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from agent.analysis.identify import Request, load_experiments
from agent.analysis.records import MAX_LINE, RecordError, time_steps
from agent.ident import Experiment, Settings
from agent.ident import job as jobs
from agent.ident.aircraft.airangles import fill
from agent.ident.errors import DataError
from agent.ident.job import Outcome
from agent.logs import LogError, read_log

SWEEPABLE = ("markov", "order")


class AnalyzeError(ValueError):
    """Bad arguments or logs; the message says which and why."""


@dataclass(frozen=True)
class Case:
    """One identification: which experiments, with which settings."""

    label: str  # "1" … per excitation, or "batch"
    key: tuple[tuple[str, int], ...]  # the swept values, e.g. (("markov", 3),)
    job: jobs.Job


# The most settings one sweep runs (each an identification per excitation).
MAX_SWEEP = 200


def parse_sweep(text: str) -> tuple[str, list[int]]:
    """`markov=1:20`, `order=2:12:2` or `markov=1,2,5` → (name, values)."""
    name, sep, spec = text.partition("=")
    name = name.strip()
    if not sep or name not in SWEEPABLE:
        raise AnalyzeError(f"--sweep {text!r}: give markov=… or order=… (e.g. markov=1:20)")
    # Counted before any list is built: a range is counted and bounded arithmetically.
    if spec.count(",") >= MAX_SWEEP:
        raise AnalyzeError(
            f"--sweep {text[:40]!r}…: {spec.count(',') + 1} values; at most {MAX_SWEEP}"
        )
    try:
        if ":" in spec:
            parts = [int(v) for v in spec.split(":")]
            if len(parts) not in (2, 3):
                raise ValueError(spec)
            start, stop, step = parts if len(parts) == 3 else (*parts, 1)
            if step == 0:
                raise AnalyzeError(f"--sweep {text!r}: the step must not be 0")
            # Both ends included, counting up or down (markov=5:1:-1 is 5, 4, 3, 2, 1).
            values: Sequence[int] = range(start, stop + (1 if step > 0 else -1), step)
        else:
            values = [int(v) for v in spec.split(",")]
    except AnalyzeError:
        raise
    except ValueError:
        raise AnalyzeError(f"--sweep {text!r}: values must be integers") from None
    if not values:
        raise AnalyzeError(f"--sweep {text!r}: names no value (the step runs away from the end)")
    if len(values) > MAX_SWEEP:
        raise AnalyzeError(f"--sweep {text!r}: {len(values)} values; at most {MAX_SWEEP}")
    if min(values) < 1:
        raise AnalyzeError(f"--sweep {text!r}: values must be ≥ 1")
    return name, list(values)


def select_logs(paths: Sequence[Path], excitations: Sequence[str] | None) -> list[Path]:
    """Files as given; directories give their excitation logs (NNNN_<axes>_single|batch_…);
    `excitations` picks by running number (3 or 0003) or by plan id (header comment)."""
    files: list[Path] = []
    for path in paths:
        if path.is_dir():
            files += sorted(
                p
                for p in path.glob("*.csv")
                if re.match(r"\d{4}_(lateral|longitudinal|full)_", p.name)
            )
        elif path.exists():
            files.append(path)
        else:
            raise AnalyzeError(f"{path}: no such file or directory")
    if excitations:
        chosen = []
        for wanted in excitations:
            match = [f for f in files if _number(f) == wanted.zfill(4) or _plan(f) == wanted]
            if not match:
                raise AnalyzeError(f"no excitation log {wanted!r} among {len(files)} file(s)")
            chosen += match
        files = chosen
    if not files:
        raise AnalyzeError("no excitation logs to analyze")
    return files


def _number(path: Path) -> str:
    return path.name[:4]


def _header(path: Path, pattern: str) -> str | None:
    """The first match of `pattern`'s group in the log's comment lines."""
    with path.open(encoding="utf-8", errors="replace") as handle:
        while (line := handle.readline(MAX_LINE)).startswith("#"):  # never a whole /dev/zero
            found = re.search(pattern, line)
            if found:
                return found.group(1)
    return None


def _plan(path: Path) -> str | None:
    return _header(path, r"excitation plan (\S+),")


def flown_on_sticks(path: Path) -> bool:
    """Whether the agent's own log says its run was played on the sticks with the autopilot's
    loops closed (agent.logs: "flown on the sticks (FBWA: closed loop)"): identified as a
    closed-loop record, as onboard (`Settings.closed_loop`)."""
    return own_log(path) and _header(path, r"(flown on the sticks)") is not None


def own_log(path: Path) -> bool:
    """Whether `path` is one of the agent's own logs (its first line says so): its inputs are
    then the surface potentiometers' samples of moving surfaces, which the settings of
    `held_inputs = "auto"` treat as not held (`Settings.from_config`'s `sampled_inputs`)."""
    try:
        with path.open(encoding="utf-8", errors="replace") as handle:
            return handle.readline(MAX_LINE).startswith("# suas-sysid")
    except OSError as exc:
        raise AnalyzeError(f"{path}: cannot be read ({exc.strerror or exc})") from exc


def build_cases(
    request: Request,
    roles: Sequence[str | None],
    settings: Settings,
    *,
    batch: bool,
    sweep: tuple[str, list[int]] | None,
    input_roles: Sequence[str | None] = (),
) -> tuple[list[Case], float]:
    """Every identification the analysis needs, and the records' sample time. `settings`:
    made with `sampled_inputs` when any of the logs is the agent's own (`own_log`), as onboard;
    a log flown on the sticks (`flown_on_sticks`) is identified as a closed-loop record, and a
    batch with one, as onboard. `roles` and `input_roles`: the outputs' and inputs' roles
    (None where a channel has none)."""
    data, contexts, rates, commands = [], [], [], []
    closed = [flown_on_sticks(Path(p)) for p in request.paths]
    for path in request.paths:
        exp, dt, declared = _experiment(Path(path), request)
        data.append((exp.u, exp.y))
        contexts.append((exp.operating_point, exp.navigation, exp.air_angles, exp.flight))
        rates.append(dt)
        commands.append(declared)
    if settings.held_inputs is None and set(request.inputs) <= frozenset.intersection(*commands):
        settings = replace(settings, held_inputs=True)  # servo outputs, as `sysid identify`
    dt = rates[0]
    if any(abs(r - dt) > 0.01 * dt for r in rates):
        raise AnalyzeError(f"the logs are sampled at different rates ({sorted(set(rates))} s)")
    pairs = list(zip(data, contexts, strict=True))
    if batch:
        groups = [("batch", tuple(data), tuple(contexts), any(closed))]
    else:
        groups = [(str(k + 1), (d,), (c,), closed[k]) for k, (d, c) in enumerate(pairs)]
    keys: list[tuple[tuple[str, int], ...]] = [()]
    if sweep is not None:
        keys = [((sweep[0], v),) for v in sweep[1]]
    cases = []
    for key in keys:
        for label, group, context, sticks in groups:
            case_settings = replace(
                settings, **dict(key), closed_loop=settings.closed_loop or sticks
            )
            job = jobs.Job(
                model_id=label,
                axes="analysis",
                record_dt=dt,
                inputs=tuple(request.inputs),
                outputs=tuple(request.outputs),
                roles=tuple(r or "" for r in roles),
                experiments=group,
                settings=case_settings,
                contexts=context,
                input_roles=tuple(r or "" for r in input_roles),
            )
            cases.append(Case(label, key, job))
    return cases, dt


def _experiment(path: Path, request: Request) -> tuple[Experiment, float, frozenset[str]]:
    """(experiment, dt, the columns it declares commands) of one log. The agent's own logs go
    through the agent's window code (edge rows without data cut, gaps up to 0.1 s bridged,
    trim removed), as onboard; any other record through `sysid identify`'s strict reader.
    Either way the experiment carries its operating point and, where the log has the INS's
    heading and velocities (`Request.navigation`), its navigation, as onboard."""
    if not own_log(path):
        single = replace(request, paths=(path,))
        try:
            loaded = load_experiments(single)
        except RecordError as exc:
            raise AnalyzeError(str(exc)) from exc
        if len(loaded.experiments) > 1:  # one record, one run: its segments are not one
            raise AnalyzeError(
                f"{path}: {'; '.join(loaded.notes)}; a replay takes one uniform record: "
                "choose a segment with --start/--end (sysid identify takes them all as a batch)"
            )
        return loaded.experiments[0], loaded.dt, loaded.commands
    try:
        # Only the columns used are kept: memory goes with them, not with the log.
        air = request.air_angles
        synthesisable = (air.alpha, air.beta) if air is not None and air.mode != "vanes" else ()
        used = (
            "time",
            *request.inputs,
            *request.outputs,
            *request.navigation,
            *(air.needed if air is not None else ()),
            *request.flight.values(),
        )
        columns, rows = read_log(path, used)
    except LogError as exc:  # names the line and column
        raise AnalyzeError(f"{path}: {exc}") from exc
    except (OSError, ValueError) as exc:
        raise AnalyzeError(f"{path}: not a readable log ({exc})") from exc
    missing = [
        n
        for n in ("time", *request.inputs, *request.outputs)
        if n not in columns and n not in synthesisable
    ]
    if missing:
        raise AnalyzeError(f"{path}: no column {', '.join(missing)}")
    if rows.shape[0] < 3:
        raise AnalyzeError(
            f"{path}: {rows.shape[0]} data row(s) after the header: the log was cut short "
            "(a power cut or a full disk while it was written)"
        )
    time = rows[:, columns.index("time")]
    _check_time(path, time)
    time = time - time[0]
    keep = np.ones(time.size, bool)
    if request.start is not None:
        keep &= time >= request.start
    if request.end is not None:
        keep &= time <= request.end
    if keep.sum() < 3:
        raise AnalyzeError(f"{path}: fewer than 3 samples between --start and --end")
    # The recorder's rate from the header, as onboard (the agent's sample time is 1/rate, not
    # the µs-rounded times); logs written before the header named it: the median step.
    rate = _header(path, r"recorded at (\S+) Hz")
    dt = 1.0 / float(rate) if rate else float(np.median(np.diff(time)))
    present = [n for n in dict.fromkeys(used[1:]) if n in columns]
    values = {n: rows[keep, columns.index(n)] for n in present}
    made = None
    try:
        if air is not None:
            values, made = fill(values, request.outputs, air)
        (u, y), trim = jobs.window_and_trim(
            values, request.inputs, request.outputs, dt, max(request.trim_seconds, dt)
        )
    except (DataError, KeyError, ValueError) as exc:
        raise AnalyzeError(f"{path}: {exc}") from exc
    operating_point = np.array(list(trim["outputs"].values()))
    if request.trim_seconds <= 0:  # --trim none: the data as recorded
        u = u + np.array(list(trim["inputs"].values()))
        y = y + operating_point
        operating_point = np.zeros_like(operating_point)
    nav = jobs.window_navigation(values, request.inputs, request.outputs, request.navigation)
    flight = tuple(request.flight.items())
    states = jobs.window_flight(values, request.inputs, request.outputs, flight)
    experiment = Experiment(
        u, y, operating_point=operating_point, navigation=nav, air_angles=made, flight=states
    )
    return experiment, dt, frozenset()


def _check_time(path: Path, time: np.ndarray) -> None:
    """The log's time column has a value in every row and increases, as `sysid identify`
    requires of a record: an empty cell or a repeated time is named, not identified across."""
    missing = np.flatnonzero(~np.isfinite(time))
    if missing.size:
        raise AnalyzeError(f"{path}: data row {missing[0] + 1} has no time")
    try:
        time_steps(path, time, ".6f")  # monotonic clock seconds: to the µs, not 6 digits
    except RecordError as exc:
        raise AnalyzeError(str(exc)) from None


def run_cases(
    cases: Sequence[Case],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[Outcome]:
    """Run every case's job; results in case order. `scheduler`: a Dask cluster address."""
    done = 0

    def tick():
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, len(cases))

    if scheduler is not None:
        from dask.distributed import Client, as_completed

        with Client(scheduler) as client:
            futures = client.map(jobs.run, [c.job for c in cases], pure=False)
            for _ in as_completed(futures):
                tick()
            return client.gather(futures)
    if workers <= 1 or len(cases) == 1:
        results = []
        for case in cases:
            results.append(jobs.run(case.job))
            tick()
        return results
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context) as pool:
        futures = [pool.submit(jobs.run, c.job) for c in cases]
        try:
            for future in futures:
                future.result()
                tick()
        except BaseException:  # Ctrl-C: leaving the pool must not run the cases still queued
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        return [f.result() for f in futures]
