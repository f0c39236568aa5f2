"""The `sysid` command: parse arguments, load config, call in. Exit 0 ok, 1 failed, 2 bad input."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from agent.analysis import identify as identify_cmd
from agent.analysis.records import RecordError
from agent.config import Config, ConfigError, load_config
from agent.excitation.plan import PRESETS, PlanRefused, check, preset, summary
from agent.excitation.preview import PreviewError, csv_text, load_plan, parse_amplitudes, plot
from agent.ident import DataError, IdentificationFailed
from agent.ident.summary import format_text, to_dict
from drivers.decode import CODECS as DECODERS
from drivers.decode import as_json, as_text, decode_file

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
DEFAULT_CONFIG = Path("config.toml")


def _names(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise argparse.ArgumentTypeError("expected comma-separated column names")
    return names


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {value}")
    return value


def _trim(text: str) -> float:
    try:
        return identify_cmd.parse_trim(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _identification_options(parser: argparse.ArgumentParser) -> None:
    """The options `sysid identify` and `sysid analyze` share."""
    parser.add_argument("--inputs", type=_names, metavar="NAMES", help="input columns, a,b,…")
    parser.add_argument("--outputs", type=_names, metavar="NAMES", help="output columns, a,b,…")
    parser.add_argument(
        "--axes",
        choices=("lateral", "longitudinal", "full"),
        help="take inputs/outputs from the config's channel names for this axis set",
    )
    parser.add_argument("--order", type=_positive_int, metavar="N", help="model order")
    parser.add_argument("--markov", type=_positive_int, metavar="P", help="Markov parameters")
    parser.add_argument("--start", type=float, metavar="T0", help="first time used, s")
    parser.add_argument("--end", type=float, metavar="T1", help="last time used, s")
    parser.add_argument(
        "--trim",
        type=_trim,
        metavar="first:SECONDS|none",
        help="trim = mean of the first SECONDS of each record (default from config: 0.5)",
    )
    parser.add_argument(
        "--decimation",
        type=_positive_int,
        metavar="Q",
        help="decimation factor after the anti-alias filter (default: automatic; 1 = none)",
    )
    parser.add_argument(
        "--method",
        choices=("auto", "time", "frequency", "aircraft"),
        help="auto (default: aircraft when an axis's four outputs are named and neither "
        "--markov nor --order is given, else time), OKID in the time "
        "domain, OKID from averaged spectra (thesis §4.3.1), or aircraft: decoupled "
        "longitudinal and lateral models fitted in the frequency domain",
    )
    parser.add_argument(
        "--period",
        type=_positive_seconds,
        metavar="SECONDS",
        help="excitation period for --method frequency (default: detected from the inputs)",
    )
    parser.add_argument(
        "--refine",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="output-error refinement with Cramér–Rao standard errors (default from config: on)",
    )
    parser.add_argument("--config", type=Path, help="config file (default ./config.toml if any)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _replay_options(parser: argparse.ArgumentParser) -> None:
    """The logs and running options `sysid analyze` and `sysid report` share."""
    parser.add_argument("data", nargs="+", type=Path, metavar="LOG",
                        help="excitation logs, records, or a log directory")  # fmt: skip
    _identification_options(parser)
    parser.add_argument("--excitation", action="append", metavar="N|PLAN",
                        help="only this excitation log (running number or plan id)")  # fmt: skip
    parser.add_argument("--jobs", type=_positive_int, default=1, help="parallel processes")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run the identifications on this Dask cluster")  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="sysid", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    ident = sub.add_parser(
        "identify",
        help="identify a linear model from CSV flight records (OKID/ERA)",
        description="Identify one linear model from one or more CSV records (a batch).",
    )
    ident.add_argument("data", nargs="+", type=Path, metavar="DATA.csv")
    _identification_options(ident)

    analyze = sub.add_parser(
        "analyze",
        help="re-run the onboard identification on logs: per excitation, batch, sweeps, "
        "cross-validation",
        description="Re-run the agent's identification job on excitation logs (or any "
        "records) with changed settings (thesis 6.2.3).",
    )
    _replay_options(analyze)
    analyze.add_argument("--batch", action="store_true", help="one identification of all")
    analyze.add_argument("--sweep", metavar="NAME=RANGE",
                         help="markov=1:20 or order=2:12:2 or markov=1,2,5")  # fmt: skip
    analyze.add_argument("--cross", action="store_true",
                         help="each model on every other excitation (TIC_jN)")  # fmt: skip

    report = sub.add_parser(
        "report",
        help="an HTML report with figures for excitation logs",
        description="Time histories against the identified models with TIC, eigenvalues in "
        "the s-plane, Hankel singular values, Bode plots against the data, input spectra "
        "and RPF, mode tables.",
    )
    _replay_options(report)
    report.add_argument("--out", type=Path, required=True, metavar="DIR")
    report.add_argument("--nominal", type=Path, metavar="MODEL.json",
                        help="a model store file to highlight")  # fmt: skip

    excite = sub.add_parser(
        "excite",
        help="preview an excitation plan before flight",
        description="Render a plan at the command rate: CSV (default), a JSON summary, a plot.",
    )
    source = excite.add_mutually_exclusive_group(required=True)
    source.add_argument("--preset", choices=PRESETS, help="one of the thesis's plans")
    source.add_argument("--plan", type=Path, metavar="PLAN.json", help="a plan file")
    excite.add_argument("--rate", type=float, metavar="HZ", help="command rate (default: config)")
    excite.add_argument(
        "--amplitude",
        action="append",
        default=[],
        metavar="CONTROL=VALUE",
        help="preset amplitude (deg, throttle %%) from trim; repeat per control",
    )
    excite.add_argument("--csv", action="store_true", help="time and one column per control")
    excite.add_argument("--json", action="store_true", help="duration, RPF, peak, band, warnings")
    excite.add_argument("--plot", type=Path, metavar="FILE.png", help="draw the plan")
    excite.add_argument("--config", type=Path, help="config file (default ./config.toml if any)")

    decode = sub.add_parser(
        "decode",
        help="decode a raw sensor capture",
        description="Decode a raw capture (bytes as read from the port) with the drivers' codecs.",
    )
    decode.add_argument(
        "device",
        choices=sorted(DECODERS),
        metavar="DEVICE",
        help=f"one of {', '.join(sorted(DECODERS))}",
    )
    decode.add_argument("file", type=Path, metavar="FILE")
    decode.add_argument("--json", action="store_true", help="one JSON object per message")

    imp = sub.add_parser(
        "import",
        help="an autopilot log (ArduPilot .bin, PX4 .ulg) as a record for sysid identify",
        description="Map an ArduPilot DataFlash log to the channel names of `sysid identify` "
        "(attitude, rates, accelerations, airspeed, AoA/sideslip, surface outputs, SystemID "
        "records), uniformly resampled; see the README for the mapping.",
    )
    imp.add_argument("file", type=Path, metavar="FILE", help="ArduPilot .bin or PX4 .ulg")
    imp.add_argument("--out", type=Path, required=True, help="CSV to write")
    imp.add_argument("--rate", type=float, default=50.0, help="sample rate of the record, Hz")
    imp.add_argument(
        "--config", type=Path, help="config.toml whose [excitation.surfaces] maps RC outputs"
    )

    export = sub.add_parser(
        "export",
        help="identified models (and data) to MATLAB .mat or JSON",
        description="Export the models of a result log, a model store file "
        "(models/<axes>_nominal.json) or a ground log; variable names in the README.",
    )
    export.add_argument("source", type=Path, metavar="SOURCE")
    export.add_argument("--out", type=Path, required=True, help="FILE.mat or FILE.json")
    export.add_argument("--model", action="append", metavar="ID", help="only these model ids")

    aircraft = sub.add_parser(
        "sim-aircraft",
        help="run the simulated aircraft alone (JSBSim, emulated ArduPlane, sensor ptys)",
        description="Fly the simulated aircraft and print where its MAVLink port and sensor "
        "pseudo-terminals are, so `sysid agent` can be pointed at it as at a real aircraft.",
    )
    aircraft.add_argument("--aircraft", default="J3Cub", help="JSBSim aircraft (default J3Cub)")
    aircraft.add_argument("--speed-kts", type=float, default=60.0)
    aircraft.add_argument("--altitude-ft", type=float, default=1000.0)
    aircraft.add_argument(
        "--turbulence",
        type=float,
        default=0.0,
        help="Dryden intensity: 0 none, 1 light (W20 = 5 ft/s), 5 ≈ MIL-F-8785C light (15 kt)",
    )
    aircraft.add_argument("--seed", type=int, default=0)
    aircraft.add_argument(
        "--mavlink-port",
        type=_port,
        default=14555,
        help="UDP port the emulated autopilot listens on (0: any)",
    )
    aircraft.add_argument(
        "--pty-dir",
        type=Path,
        default=Path("sim"),
        help="directory for the sensor port links (default ./sim)",
    )
    aircraft.add_argument(
        "--switch-at",
        type=float,
        nargs="*",
        default=[],
        metavar="T",
        help="flip the switch at these seconds: high, low, …",
    )
    aircraft.add_argument("--no-noise", action="store_true", help="perfect sensors")
    aircraft.add_argument(
        "--sensor-rate",
        type=float,
        default=100.0,
        metavar="HZ",
        help="frame rate of the three sensors (default 100; 400 is the VN-200's IMU rate)",
    )
    aircraft.add_argument("--duration", type=float, help="stop after this many seconds")

    agent = sub.add_parser(
        "agent",
        help="run the onboard flight agent",
        description="The onboard agent: sensors, autopilot, recorder, "
        "excitation, identification, radio link; stop with Ctrl-C.",
    )
    agent.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    agent.add_argument(
        "--base",
        type=Path,
        default=Path("."),
        help="directory for logs, models and link state (default .)",
    )

    sim = sub.add_parser(
        "sim",
        help="a whole flight with no hardware, end to end",
        description="Simulated aircraft, emulated ArduPlane, sensors and "
        "radios, the real agent, and a scripted ground operator.",
    )
    sim.add_argument("--aircraft", default="J3Cub")
    sim.add_argument("--speed-kts", type=float, default=60.0)
    sim.add_argument(
        "--turbulence", type=float, default=0.0, help="Dryden intensity: 1 = light (W20 = 5 ft/s)"
    )
    sim.add_argument("--seed", type=int, default=0)
    sim.add_argument("--preset", choices=PRESETS, default="full")
    sim.add_argument(
        "--runs",
        type=_positive_int,
        default=1,
        help="excitations in a row (from the second on: TIC against the nominal)",
    )
    sim.add_argument("--keep", type=Path, metavar="DIR", help="keep logs and models in DIR")
    sim.add_argument("--json", action="store_true", help="one JSON object")
    sim.add_argument(
        "--interactive",
        action="store_true",
        help="fly it from the ground console instead of the script (the simulated pilot "
        "flips the switch 2 s after a plan is armed)",
    )

    console = sub.add_parser(
        "console",
        help="the ground console (Textual) on the XBee link",
        description="Vehicle status, excitation, identification settings, results and the "
        "model-update decision; everything received is also in the ground log.",
    )
    console.add_argument("--config", type=Path, default=Path("ground.toml"))
    console.add_argument(
        "--base",
        type=Path,
        default=Path("."),
        help="directory for the ground log, key and link state (default .)",
    )

    config = sub.add_parser("config", help="configuration tools")
    config_sub = config.add_subparsers(dest="config_command", required=True)
    check = config_sub.add_parser("check", help="validate a config file")
    check.add_argument("file", nargs="?", type=Path, default=DEFAULT_CONFIG)
    check.add_argument("--ground", action="store_true", help="the file is a ground console config")
    return parser


def _checked(convert, accept, noun: str, hint: str):
    """An argparse type: `convert` the text (else "is not a <noun>"), then `accept` the value
    (else the hint)."""

    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {noun}") from None
        if not accept(value):
            raise argparse.ArgumentTypeError(f"{text}: {hint}")
        return value

    return parse


# nan, inf, 0 and negatives refused; a UDP port from 0 (any) to 65535.
_positive_seconds = _checked(float, lambda v: math.isfinite(v) and v > 0, "number of seconds",
                             "give a finite, positive number of seconds")  # fmt: skip
_port = _checked(int, lambda p: 0 <= p <= 65535, "port number",
                 "not a UDP port: give 0 (any) to 65535")  # fmt: skip


class UsageError(Exception):
    """A command line argparse refuses: the parser that refused it, and why."""

    def __init__(self, parser: argparse.ArgumentParser, message: str):
        super().__init__(message)
        self.parser = parser


class _Parser(argparse.ArgumentParser):
    """argparse's parser (its subcommands' too), raising UsageError instead of exiting, so that
    under --json a usage error is one JSON object on stdout like every other error."""

    def error(self, message: str):  # type: ignore[override]
        raise UsageError(self, message)


def _error(command: str, message: str) -> None:
    print(f"sysid {command}: error: {message}", file=sys.stderr)
    _json_state["error"] = message


# Under --json: whether the command printed its object, and its last error message (main()
# prints the error object of a command that failed without printing one).
_json_state: dict = {"printed": False, "error": None}


def _print_json(document) -> None:
    """One JSON object on stdout, non-finite numbers as null (JSON has no NaN)."""
    print(json.dumps(_finite(document), allow_nan=False))
    _json_state["printed"] = True


def _finite(value):
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return _finite(value.tolist())
    return value


def _load_optional_config(path: Path | None) -> Config:
    if path is not None:
        return load_config(path)
    return load_config(DEFAULT_CONFIG) if DEFAULT_CONFIG.exists() else Config()


def _identification_request(args: argparse.Namespace, command: str, paths):
    """(config, request, settings) from the shared identification options; None after an
    error message."""
    try:
        config = _load_optional_config(args.config).identification
    except ConfigError as exc:
        _error(command, str(exc))
        return None
    inputs, outputs = args.inputs, args.outputs
    if args.axes is not None:
        axis_inputs, axis_outputs = config.channels.axis_set(args.axes)
        inputs, outputs = inputs or axis_inputs, outputs or axis_outputs
    if not inputs or not outputs:
        _error(command, "give --inputs and --outputs, or --axes lateral|longitudinal|full")
        return None
    trim = config.trim_seconds if args.trim is None else args.trim
    request = identify_cmd.Request(
        paths=tuple(paths),
        inputs=inputs,
        outputs=outputs,
        start=args.start,
        end=args.end,
        trim_seconds=trim,
        navigation=config.channels.navigation(),
    )
    settings = identify_cmd.settings_from(
        config,
        args.markov,
        args.order,
        decimation=args.decimation,
        refine=args.refine,
        method=args.method,
        period_s=args.period,
    )
    return config, request, settings


def cmd_identify(args: argparse.Namespace) -> int:
    prepared = _identification_request(args, "identify", args.data)
    if prepared is None:
        return EXIT_BAD_INPUT
    config, request, settings = prepared
    try:
        outcome = identify_cmd.run(request, config, settings)
    except (RecordError, DataError) as exc:
        return _fail(args, "bad input", str(exc), EXIT_BAD_INPUT)
    except IdentificationFailed as exc:
        return _fail(args, "identification failed", str(exc), EXIT_FAILED)
    if args.json:
        _print_json(to_dict(outcome.result, outcome.trim))
    else:
        print(format_text(outcome.result, outcome.records, outcome.samples))
    return EXIT_OK


def cmd_analyze(args: argparse.Namespace) -> int:
    from agent.analysis import analyze as an

    try:
        paths = an.select_logs(args.data, args.excitation)
        sweep = an.parse_sweep(args.sweep) if args.sweep else None
    except an.AnalyzeError as exc:
        _error("analyze", str(exc))
        return EXIT_BAD_INPUT
    prepared = _identification_request(args, "analyze", paths)
    if prepared is None:
        return EXIT_BAD_INPUT
    config, request, settings = prepared
    if args.cross and args.batch:
        _error("analyze", "--cross needs one model per excitation: drop --batch")
        return EXIT_BAD_INPUT
    roles = [config.channels.role_of(n) for n in request.outputs]
    input_roles = [config.channels.role_of(n) for n in request.inputs]
    try:
        cases, _ = an.build_cases(request, roles, settings, batch=args.batch, sweep=sweep,
                                  input_roles=input_roles)  # fmt: skip
    except an.AnalyzeError as exc:
        _error("analyze", str(exc))
        return EXIT_BAD_INPUT
    bar = _progress(len(cases), quiet=args.json)
    try:
        outcomes = an.run_cases(cases, workers=args.jobs, scheduler=args.scheduler,
                                progress=bar)  # fmt: skip
    except (OSError, ValueError, TimeoutError) as exc:  # a scheduler that cannot be reached
        _error("analyze", f"cannot run the jobs: {exc}")
        return EXIT_FAILED
    except ImportError as exc:  # --scheduler without Dask installed
        _error("analyze", f"--scheduler needs Dask ({exc}): pip install '.[cluster]'")
        return EXIT_BAD_INPUT
    finally:
        bar(None, None)
    report = {"logs": [str(p) for p in paths], "cases": [
        {"excitation": c.label, "setting": dict(c.key), **_case_summary(o)}
        for c, o in zip(cases, outcomes, strict=True)]}  # fmt: skip
    excitations = 1 if args.batch else len(paths)
    if sweep is not None:
        table = an.sweep_table(cases, outcomes)
        report["sweep"] = table
        report["recommended"] = an.recommend(table, excitations)
    if args.cross:
        report["cross_tic"] = an.cross_validation(cases, outcomes)
    if args.json:
        _print_json(report)
    else:
        print(_analysis_text(report, paths))
    return EXIT_OK if any(o["ok"] for o in outcomes) else EXIT_FAILED


def cmd_report(args: argparse.Namespace) -> int:
    from agent.analysis import analyze as an

    try:
        paths = an.select_logs(args.data, args.excitation)
    except an.AnalyzeError as exc:
        _error("report", str(exc))
        return EXIT_BAD_INPUT
    prepared = _identification_request(args, "report", paths)
    if prepared is None:
        return EXIT_BAD_INPUT
    config, request, settings = prepared
    nominal = None
    if args.nominal is not None:
        try:
            nominal = json.loads(args.nominal.read_text())
            nominal = {"model_id": nominal["model_id"], "modes": nominal["result"]["modes"]}
        except (OSError, ValueError, KeyError, TypeError) as exc:
            _error("report", f"{args.nominal}: not a model store file ({exc})")
            return EXIT_BAD_INPUT
    roles = [config.channels.role_of(n) for n in request.outputs]
    input_roles = [config.channels.role_of(n) for n in request.inputs]
    try:
        cases, _ = an.build_cases(request, roles, settings, batch=False, sweep=None,
                                  input_roles=input_roles)  # fmt: skip
    except an.AnalyzeError as exc:
        _error("report", str(exc))
        return EXIT_BAD_INPUT
    bar = _progress(len(cases), quiet=False)
    try:
        outcomes = an.run_cases(cases, workers=args.jobs, scheduler=args.scheduler,
                                progress=bar)  # fmt: skip
    except (OSError, ValueError, TimeoutError) as exc:  # a scheduler that cannot be reached
        _error("report", f"cannot run the jobs: {exc}")
        return EXIT_FAILED
    except ImportError as exc:  # --scheduler without Dask installed
        _error("report", f"--scheduler needs Dask ({exc}): pip install '.[cluster]'")
        return EXIT_BAD_INPUT
    finally:
        bar(None, None)
    from agent.analysis.report import write

    try:
        page = write(args.out, paths, cases, outcomes, nominal)
    except OSError as exc:
        _error("report", f"{args.out}: cannot be written ({exc.strerror or exc})")
        return EXIT_FAILED
    identified = sum(o["ok"] for o in outcomes)
    if args.json:
        _print_json({"page": str(page), "identified": identified, "excitations": len(outcomes)})
    else:
        print(f"{page}: {identified} of {len(outcomes)} excitation(s) identified")
    return EXIT_OK if any(o["ok"] for o in outcomes) else EXIT_FAILED


def _case_summary(outcome: dict) -> dict:
    if not outcome["ok"]:
        return {"ok": False, "reason": outcome["reason"]}
    r = outcome["result"]
    modes = [{"name": m["name"], "eigenvalue": m["eigenvalue"]} for m in r["modes"]]
    refinement = r.get("refinement")
    return {"ok": True, "markov": r["markov"], "order": r["order"], "tic_avg": r["tic_avg"],
            "modes": modes, "converged": refinement["converged"] if refinement else None,
            "warnings": list(r.get("warnings", ()))}  # fmt: skip


def _progress(total: int, quiet: bool):
    """A progress bar on stderr (tqdm) for long analyses; call with (None, None) to close."""
    if quiet or total < 2:
        return lambda done, of: None
    from tqdm import tqdm

    bar = tqdm(total=total, unit="id", file=sys.stderr, leave=False,
               disable=not sys.stderr.isatty())  # fmt: skip

    def update(done, of):
        if done is None:
            bar.close()
        else:
            bar.n = done
            bar.refresh()

    return update


def _analysis_text(report: dict, paths) -> str:
    lines = [f"{len(paths)} log(s): " + ", ".join(Path(p).name for p in paths)]
    for case in report["cases"]:
        setting = " ".join(f"{k}={v}" for k, v in case["setting"].items())
        head = f"excitation {case['excitation']}" + (f" ({setting})" if setting else "")
        if not case["ok"]:
            lines.append(f"{head}: failed: {case['reason']}")
            continue
        modes = ", ".join(f"{m['name']} {complex(*m['eigenvalue']):.3f}"
                          for m in case["modes"] if m["name"])  # fmt: skip
        lines.append(f"{head}: p {case['markov']}, n {case['order']}, "
                     f"TIC_avg {case['tic_avg']:.3f}; {modes or 'no named mode'}")  # fmt: skip
    if "sweep" in report:
        lines.append("")
        lines.append(f"{'setting':<14}{'TIC_avg':>9}  {'ok':>3}  modes (worst spread across "
                     "excitations)")  # fmt: skip
        for row in report["sweep"]:
            setting = " ".join(f"{k}={v}" for k, v in row["setting"].items())
            tic = "–" if row["tic_avg"] is None else f"{row['tic_avg']:.4f}"
            spread = ", ".join(f"{n} {100 * s:.0f}%" for n, s in row["spread"].items())
            lines.append(f"{setting:<14}{tic:>9}  {row['identified']:>3}  {spread or '–'}")
        best = report["recommended"]
        chosen = " ".join(f"{k}={v}" for k, v in best["setting"].items()) if best else None
        lines.append(f"recommended: {chosen or 'none (nothing identified every time)'}")
    if "cross_tic" in report:
        lines.append("")
        lines.append("TIC_avg of model i (rows) on excitation j (columns):")
        for k, row in enumerate(report["cross_tic"], start=1):
            cells = " ".join("    –" if v is None else f"{v:5.3f}" for v in row)
            lines.append(f"  {k:>2}: {cells}")
    return "\n".join(lines)


def _fail(args: argparse.Namespace, kind: str, message: str, code: int) -> int:
    _error("identify", f"{kind}: {message}")
    if args.json:
        _print_json({"error": {"kind": kind, "message": message, "exit": code}})
    return code


def cmd_excite(args: argparse.Namespace) -> int:
    try:
        config = _load_optional_config(args.config)
        rate = config.excitation.rate_hz if args.rate is None else args.rate
        if not 1.0 <= rate <= 1000.0:
            raise PreviewError(f"--rate must be within 1–1000 Hz, got {rate:g}")
        if args.plan is not None:
            plan = load_plan(args.plan)
        else:
            plan = preset(args.preset, parse_amplitudes(args.amplitude))
        timeline = check(plan, rate, config.excitation.surfaces, config.excitation.envelope)
    except (ConfigError, PreviewError, PlanRefused, ValueError) as exc:
        _error("excite", str(exc))
        return EXIT_BAD_INPUT
    columns = {n: getattr(config.identification.channels, n) for n in timeline.values}
    report = summary(timeline, config.excitation.surfaces)
    for warning in report["warnings"]:
        print(f"sysid excite: warning: {warning}", file=sys.stderr)
    if args.plot is not None:
        try:
            plot(timeline, report, columns, args.plot)
        except ValueError as exc:  # PreviewError, or matplotlib's unknown file format
            _error("excite", str(exc))
            return EXIT_BAD_INPUT
    if args.json:
        _print_json(report)
    elif args.csv or args.plot is None:
        sys.stdout.write(csv_text(timeline, columns))
    return EXIT_OK


def cmd_decode(args: argparse.Namespace) -> int:
    try:
        args.file.open("rb").close()
    except OSError as exc:
        _error("decode", f"{args.file}: cannot be read ({exc.strerror or exc})")
        return EXIT_BAD_INPUT
    messages, stats = decode_file(args.device, args.file)
    try:
        if args.json:  # one object: the messages and the stream's statistics
            _print_json({"messages": [as_json(m) for m in messages], "stats": stats.as_dict()})
        else:
            for message in messages:
                print(as_text(message))
            print("stats: " + ", ".join(f"{k} {v}" for k, v in stats.as_dict().items()))
    except BrokenPipeError:  # the reader (head, less) went away: nothing more to say
        sys.stdout = None
    return EXIT_OK


def cmd_import(args: argparse.Namespace) -> int:
    from agent.analysis.importers import LogImportError, import_log

    try:
        config = _load_optional_config(args.config)
    except ConfigError as exc:
        _error("import", str(exc))
        return EXIT_BAD_INPUT
    if not 1.0 <= args.rate <= 1000.0:
        _error("import", f"--rate {args.rate:g}: give 1 to 1000 Hz")
        return EXIT_BAD_INPUT
    if args.out.exists() and args.out.resolve() == args.file.resolve():
        _error("import", f"{args.out}: that is the log being imported; give another --out")
        return EXIT_BAD_INPUT
    try:
        imported = import_log(args.file, config.excitation.surfaces, args.rate)
        args.out.write_text(imported.csv())
    except LogImportError as exc:
        _error("import", str(exc))
        return EXIT_BAD_INPUT
    except OSError as exc:
        _error("import", f"{args.out}: cannot be written ({exc.strerror or exc})")
        return EXIT_FAILED
    span = imported.time[-1] if len(imported.time) else 0.0
    print(f"{args.out}: {len(imported.time)} rows over {span:.1f} s at {args.rate:g} Hz; "
          f"columns {', '.join(imported.columns)}")  # fmt: skip
    for note in imported.notes:
        print(f"note: {note}")
    if imported.missing:
        print(f"not in the log: {', '.join(imported.missing)}")
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    from agent.analysis.export import ExportError, load_models, to_json, to_mat

    suffix = args.out.suffix.lower()
    if suffix not in (".mat", ".json"):
        _error("export", f"{args.out}: give a .mat or .json file to write")
        return EXIT_BAD_INPUT
    try:
        models = load_models(args.source)
    except ExportError as exc:
        _error("export", str(exc))
        return EXIT_BAD_INPUT
    if models.skipped:
        more = " …" if len(models.skipped) > 10 else ""
        lines = ", ".join(map(str, models.skipped[:10])) + more
        print(f"sysid export: warning: {args.source}: {len(models.skipped)} line(s) not JSON "
              f"and not exported (line {lines}); the rest is", file=sys.stderr)  # fmt: skip
    if args.model:
        unknown = sorted(set(args.model) - {m["id"] for m in models})
        if unknown:
            _error("export", f"{args.source}: no model {', '.join(unknown)}")
            return EXIT_BAD_INPUT
        models = [m for m in models if m["id"] in args.model]
    try:
        if suffix == ".mat":
            to_mat(models, args.out)
        else:
            args.out.write_text(to_json(models))
    except OSError as exc:
        _error("export", f"{args.out}: cannot be written ({exc.strerror or exc})")
        return EXIT_FAILED
    print(f"{args.out}: {len(models)} model(s): {', '.join(m['id'] for m in models)}")
    return EXIT_OK


def cmd_sim_aircraft(args: argparse.Namespace) -> int:
    import asyncio

    from agent.sim.aircraft import AircraftOptions, check_sensor_rate, serve
    from agent.sim.plant import PlantError

    options = AircraftOptions(
        aircraft=args.aircraft,
        speed_kts=args.speed_kts,
        altitude_ft=args.altitude_ft,
        turbulence=args.turbulence,
        seed=args.seed,
        noise=not args.no_noise,
        mavlink_port=args.mavlink_port,
        sensor_rate_hz=args.sensor_rate,
    )
    try:
        check_sensor_rate(args.sensor_rate)
    except ValueError as exc:
        _error("sim-aircraft", str(exc))
        return EXIT_BAD_INPUT
    try:
        asyncio.run(
            serve(
                options,
                args.pty_dir,
                args.duration,
                tuple(args.switch_at),
                announce=lambda text: print(text, flush=True),
            )
        )
    except PlantError as exc:
        _error("sim-aircraft", str(exc))
        return EXIT_BAD_INPUT
    except OSError as exc:
        _error("sim-aircraft", f"cannot start: {exc}")
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        pass
    return EXIT_OK


def cmd_agent(args: argparse.Namespace) -> int:
    import asyncio

    from agent.runtime import serve
    from drivers.xbee.driver import RadioError

    try:
        config = load_config(args.config)
        text = args.config.read_text()
    except ConfigError as exc:
        _error("agent", str(exc))
        return EXIT_BAD_INPUT
    listener = _log_to_stderr_off_the_loop()
    try:
        asyncio.run(serve(config, text, args.base))
    except (OSError, ValueError, RadioError) as exc:  # a port that cannot open, a bad key file
        _error("agent", str(exc))
        return EXIT_FAILED
    finally:
        listener.stop()
    return EXIT_OK


def _log_to_stderr_off_the_loop():
    """INFO and up to stderr through a queue and a listener thread: a write to stderr (a file,
    a pipe to journald) can block for 0.1 s when the disk is busy, and the loop thread must
    never wait on it. Returns the started listener."""
    import logging.handlers
    import queue

    records: queue.SimpleQueue = queue.SimpleQueue()
    console = logging.StreamHandler(sys.stderr)
    console.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    listener = logging.handlers.QueueListener(records, console)
    root = logging.getLogger()
    root.setLevel(logging.INFO)
    root.addHandler(logging.handlers.QueueHandler(records))
    listener.start()
    return listener


def cmd_sim(args: argparse.Namespace) -> int:
    import asyncio

    from agent.sim.flight import SimError, SimOptions, fly, format_report
    from agent.sim.plant import PlantError

    progress = None if args.json else (lambda text: print(text, flush=True))
    options = SimOptions(
        aircraft=args.aircraft,
        speed_kts=args.speed_kts,
        turbulence=args.turbulence,
        seed=args.seed,
        preset=args.preset,
        runs=args.runs,
        directory=args.keep,
        progress=progress,
    )
    if args.interactive:
        from agent.sim.flight import interactive

        try:
            asyncio.run(interactive(options))
        except (PlantError, SimError) as exc:
            _error("sim", str(exc))
            return EXIT_FAILED
        return EXIT_OK
    try:
        report = asyncio.run(fly(options))
    except (PlantError, SimError) as exc:
        _error("sim", str(exc))
        return EXIT_BAD_INPUT if isinstance(exc, PlantError) else EXIT_FAILED
    if args.json:
        _print_json(report)
    else:
        print(format_report(report))
    return EXIT_OK if not report["failure"] else EXIT_FAILED


def cmd_console(args: argparse.Namespace) -> int:
    import asyncio

    from agent.clock import LoopClock
    from agent.ground.app import Console
    from agent.ground.config import GroundConfig
    from agent.ground.station import GroundStation
    from drivers.xbee.driver import RadioError

    try:
        config = load_config(args.config, GroundConfig)
    except ConfigError as exc:
        _error("console", str(exc))
        return EXIT_BAD_INPUT

    async def run() -> None:
        station = GroundStation(config, LoopClock(), base=args.base)
        try:
            await station.open()  # a port or key problem is reported before the screen opens
        except BaseException:
            await station.close()
            raise
        await Console(station).run_async()

    try:
        asyncio.run(run())
    except (OSError, ValueError, RadioError) as exc:
        _error("console", str(exc))
        return EXIT_FAILED
    return EXIT_OK


def cmd_config_check(args: argparse.Namespace) -> int:
    from agent.ground.config import GroundConfig

    try:
        load_config(args.file, GroundConfig if args.ground else Config)
    except ConfigError as exc:
        _error("config check", str(exc))
        return EXIT_BAD_INPUT
    print(f"{args.file}: ok")
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `sysid` console script. Under `--json` an unexpected error (a bug)
    still leaves exactly one JSON object on stdout; its traceback goes to stderr."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(argv)
    except UsageError as exc:
        exc.parser.print_usage(sys.stderr)
        _error(exc.parser.prog.removeprefix("sysid "), str(exc))
        if "--json" in argv:
            _print_json({"error": {"kind": "usage", "message": str(exc), "exit": EXIT_BAD_INPUT}})
        return EXIT_BAD_INPUT
    _json_state.update(printed=False, error=None)
    try:
        code = _dispatch(args)
        if getattr(args, "json", False) and not _json_state["printed"]:
            # A command that ended without its object: its error (every error path says one).
            message = _json_state["error"] or f"exit {code}"
            _print_json({"error": {"kind": "error" if code else "none", "message": message,
                                   "exit": code}})  # fmt: skip
        return code
    except Exception as exc:
        if not getattr(args, "json", False):
            raise
        import traceback

        traceback.print_exc()
        message = f"internal error: {type(exc).__name__}: {exc}"
        _print_json({"error": {"kind": "internal", "message": message, "exit": EXIT_FAILED}})
        return EXIT_FAILED


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "identify":
        return cmd_identify(args)
    if args.command == "analyze":
        return cmd_analyze(args)
    if args.command == "report":
        return cmd_report(args)
    if args.command == "excite":
        return cmd_excite(args)
    if args.command == "decode":
        return cmd_decode(args)
    if args.command == "sim-aircraft":
        return cmd_sim_aircraft(args)
    if args.command == "import":
        return cmd_import(args)
    if args.command == "export":
        return cmd_export(args)
    if args.command == "agent":
        return cmd_agent(args)
    if args.command == "sim":
        return cmd_sim(args)
    if args.command == "console":
        return cmd_console(args)
    return cmd_config_check(args)
