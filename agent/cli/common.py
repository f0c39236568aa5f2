"""What the `sysid` commands share: exit codes, errors, JSON output, argument types, options,
config loading.

Light on purpose: `sysid --help` imports this and every command's `add_parser`, so anything
heavy (numpy, scipy, pydantic, the simulator) is imported inside a command's `run`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
EXIT_INTERRUPTED = 130  # the shell's code for a command ended by SIGINT (128 + 2)
DEFAULT_CONFIG = Path("config.toml")


class CommandError(Exception):
    """Why a command stops: `message` (stderr, and under --json the error object), the exit
    code, and the error's kind (shown before the message unless it is plain "error")."""

    def __init__(self, message: str, code: int = EXIT_BAD_INPUT, kind: str = "error"):
        super().__init__(message)
        self.message, self.code, self.kind = message, code, kind


def refused(message: str) -> CommandError:
    """Bad input: exit 2."""
    return CommandError(message, EXIT_BAD_INPUT)


def failed(message: str) -> CommandError:
    """The command could not do its work: exit 1."""
    return CommandError(message, EXIT_FAILED)


class UsageError(Exception):
    """A command line argparse refuses: the parser that refused it, and why."""

    def __init__(self, parser: argparse.ArgumentParser, message: str):
        super().__init__(message)
        self.parser = parser


class Parser(argparse.ArgumentParser):
    """argparse's parser (its subcommands' too), raising UsageError instead of exiting, so that
    under --json a usage error is one JSON object on stdout like every other error."""

    def error(self, message: str):  # type: ignore[override]
        raise UsageError(self, message)


# Under --json: whether the command printed its object, and its last error message (main()
# prints the error object of a command that failed without printing one).
json_state: dict = {"printed": False, "error": None}


def say_error(command: str, message: str) -> None:
    print(f"sysid {command}: error: {message}", file=sys.stderr)
    json_state["error"] = message


def print_json(document) -> None:
    """One JSON object on stdout, non-finite numbers as null (JSON has no NaN)."""
    print(json.dumps(finite(document), allow_nan=False))
    json_state["printed"] = True


def print_json_items(key: str, items: Iterable, rest: Callable[[], dict]) -> None:
    """One JSON object on stdout, `{key: [*items], **rest()}`, written item by item so that
    a long list is never held whole; `rest` is called after the last item. An error among the
    items still closes the object, with an "error" member, before it goes on up."""
    out = sys.stdout
    out.write("{" + json.dumps(key) + ": [")
    json_state["printed"] = True
    count = 0
    try:
        for item in items:
            out.write((", " if count else "") + json.dumps(finite(item), allow_nan=False))
            count += 1
    except BrokenPipeError:  # the reader went away: nothing can be closed
        raise
    except BaseException as exc:
        code = (
            exc.code
            if isinstance(exc, CommandError)
            else EXIT_INTERRUPTED
            if isinstance(exc, KeyboardInterrupt)
            else EXIT_FAILED
        )
        message = f"after {count} item(s): {type(exc).__name__}: {exc}"
        error = {"kind": "error", "message": message, "exit": code}
        out.write("], " + json.dumps({"error": error})[1:] + "\n")
        raise
    tail = json.dumps(finite(rest()), allow_nan=False)
    out.write("]" + (", " + tail[1:] if tail != "{}" else "}") + "\n")


def finite(value):
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return finite(value.tolist())
    return value


def names(text: str) -> tuple[str, ...]:
    found = tuple(n.strip() for n in text.split(",") if n.strip())
    if not found:
        raise argparse.ArgumentTypeError("expected comma-separated column names")
    return found


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {value}")
    return value


def checked(convert, accept, noun: str, hint: str):
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
positive_seconds = checked(
    float,
    lambda v: math.isfinite(v) and v > 0,
    "number of seconds",
    "give a finite, positive number of seconds",
)
knots = checked(
    float,
    lambda v: math.isfinite(v) and v > 0,
    "speed in knots",
    "give a finite, positive speed in knots",
)
port = checked(
    int, lambda p: 0 <= p <= 65535, "port number", "not a UDP port: give 0 (any) to 65535"
)
# The simulator's Dryden intensity in units of light turbulence (W20 = 5 ft/s): 0 is calm air,
# and MIL-F-8785C's severe turbulence (W20 = 45 kt, 76 ft/s) is about 15.
MAX_TURBULENCE = 15.0
turbulence = checked(
    float,
    lambda v: 0.0 <= v <= MAX_TURBULENCE,  # NaN fails both
    "turbulence intensity",
    f"give 0 (calm) to {MAX_TURBULENCE:g} (severe); 1 is light (W20 = 5 ft/s)",
)


def trim(text: str) -> float:
    from agent.analysis.identify import parse_trim

    try:
        return parse_trim(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def units(text: str) -> dict[str, str]:
    from agent.analysis.units import UnitError, parse_units

    try:
        return parse_units(text)
    except UnitError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _navigation_role(channels, name: str) -> str | None:
    """The navigation role (psi, vn, ve, vd) a column name carries, or None."""
    from agent.channels import NAVIGATION_ROLES

    return next((r for r in NAVIGATION_ROLES if getattr(channels, r) == name), None)


def identification_options(parser: argparse.ArgumentParser) -> None:
    """The options `sysid identify`, `analyze` and `report` share."""
    parser.add_argument("--inputs", type=names, metavar="NAMES", help="input columns, a,b,…")
    parser.add_argument("--outputs", type=names, metavar="NAMES", help="output columns, a,b,…")
    parser.add_argument(
        "--axes",
        choices=("lateral", "longitudinal", "full"),
        help="take inputs/outputs from the config's channel names for this axis set",
    )
    parser.add_argument("--order", type=positive_int, metavar="N", help="model order")
    parser.add_argument("--markov", type=positive_int, metavar="P", help="Markov parameters")
    parser.add_argument(
        "--units",
        type=units,
        metavar="NAME=UNIT,…",
        help="the unit of a column where its header does not say (alpha=deg, p=deg/s, "
        "airspeed=kt): converted to the unit its role is identified in",
    )
    parser.add_argument(
        "--select",
        action="store_true",
        help="model-structure selection (whole-aircraft method): derivatives whose standard "
        "error is above their value fixed at 0, listed in the result; judge it with --validate",
    )
    parser.add_argument(
        "--closed-loop",
        action="store_true",
        help="the record was flown with the autopilot's loops closed (FBWA: the manoeuvre on "
        "the sticks): the lateral axis is refined by prediction error (whole-aircraft method; "
        "without it, only where output error's roll mode is imprecise)",
    )
    parser.add_argument("--start", type=float, metavar="T0", help="first time used, s")
    parser.add_argument("--end", type=float, metavar="T1", help="last time used, s")
    parser.add_argument(
        "--trim",
        type=trim,
        metavar="first:SECONDS|none",
        help="trim = mean of the first SECONDS of each record (default from config: 0.5)",
    )
    parser.add_argument(
        "--decimation",
        type=positive_int,
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
        "--air-angles",
        choices=("auto", "vanes", "synthesised"),
        help="alpha and beta from the vanes, or synthesised from the INS velocity, attitude "
        "and an estimated wind (default from config: auto, the vanes' where a record has them)",
    )
    parser.add_argument(
        "--period",
        type=positive_seconds,
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


def replay_options(parser: argparse.ArgumentParser) -> None:
    """The logs and running options `sysid analyze` and `sysid report` share."""
    parser.add_argument(
        "data",
        nargs="+",
        type=Path,
        metavar="LOG",
        help="excitation logs, records, or a log directory",
    )
    identification_options(parser)
    parser.add_argument(
        "--excitation",
        action="append",
        metavar="N|PLAN",
        help="only this excitation log (running number or plan id)",
    )
    parser.add_argument("--jobs", type=positive_int, default=1, help="parallel processes")
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", help="run the identifications on this Dask cluster"
    )


def service_options(parser: argparse.ArgumentParser, config: Path, base_holds: str) -> None:
    """The config file and the state directory of the long-running commands (agent, console)."""
    parser.add_argument("--config", type=Path, default=config)
    parser.add_argument(
        "--base",
        type=Path,
        default=Path("."),
        help=f"directory for {base_holds} (default .)",
    )


def aircraft_arguments(parser: argparse.ArgumentParser) -> None:
    """The options that choose and trim the simulated aircraft (`sysid sim`, `sim-aircraft`)."""
    parser.add_argument(
        "--aircraft",
        default="J3Cub",
        help="the JSBSim aircraft to fly (default J3Cub; `sysid sim --list-aircraft` lists "
        "them, with the speeds the benchmark's are flown at)",
    )
    parser.add_argument(
        "--speed-kts",
        type=knots,
        default=None,
        metavar="KT",
        help="calibrated airspeed to trim at, kt (default: the benchmark's for its six "
        "aircraft, e.g. 60 for the J3Cub, 150 for the t6texan2; needed for any other)",
    )
    parser.add_argument(
        "--altitude-ft",
        type=float,
        default=None,
        metavar="FT",
        help="height above the ground to trim at, ft (default 1000; 3000 for the sgs126: a "
        "glider sinks all flight)",
    )
    parser.add_argument(
        "--turbulence",
        type=turbulence,
        default=0.0,
        help="Dryden intensity: 0 none, 1 light (W20 = 5 ft/s), at most 15 (severe)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="JSBSim's random seed: the turbulence and the sensors' noise (0 and 1 give one "
        "turbulence sequence); the same seed flies the same air",
    )
    parser.add_argument(
        "--no-vanes",
        action="store_true",
        help="air data with the airspeed only (no α, β vanes): the agent synthesises α and β "
        "from the INS",
    )
    parser.add_argument(
        "--fbwa",
        action="store_true",
        help="the emulated ArduPlane flies in FBWA (its stabilised mode): plans play on the "
        "sticks, its laws fly the surfaces (closed-loop excitation)",
    )


def aircraft_options(args: argparse.Namespace, **more):
    """The simulated aircraft's options (agent.sim.aircraft) from `aircraft_arguments`, and
    `more`; an aircraft whose trim speed is not known and not given is refused."""
    from agent.sim.aircraft import AircraftOptions, flown_at
    from agent.sim.ardupilot import FBWA, MANUAL

    try:
        speed, altitude = flown_at(args.aircraft, args.speed_kts, args.altitude_ft)
    except ValueError as exc:
        raise refused(str(exc)) from None
    return AircraftOptions(
        aircraft=args.aircraft,
        speed_kts=speed,
        altitude_ft=altitude,
        turbulence=args.turbulence,
        seed=args.seed,
        vanes=not args.no_vanes,
        mode=FBWA if getattr(args, "fbwa", False) else MANUAL,
        **more,
    )


def read_config(path: Path, model=None):
    """The config file at `path`, validated as `model` (the agent's Config if None); a bad
    file is refused (exit 2)."""
    from agent.config import ConfigError, load_config

    try:
        return load_config(path) if model is None else load_config(path, model)
    except ConfigError as exc:
        raise refused(str(exc)) from None


def load_optional_config(path: Path | None):
    """The config at `path`, else ./config.toml if there is one, else the defaults; a bad
    file is refused (exit 2)."""
    if path is None and not DEFAULT_CONFIG.exists():
        from agent.config import Config

        return Config()
    return read_config(DEFAULT_CONFIG if path is None else path)


def config_input(path: Path | None) -> dict:
    """The config file a command reads (`load_optional_config`'s), as an input of
    `outputs_for`."""
    if path is None and not DEFAULT_CONFIG.exists():
        return {}
    return {DEFAULT_CONFIG if path is None else path: "the config file"}


def outputs_for(inputs: dict):
    """The one way a command writes files (`agent.outputs.Outputs`): each output checked
    against `inputs` (path → what it is) and the other outputs, written whole or not at all."""
    from agent.outputs import Outputs

    return Outputs(inputs)


def claim(outputs, path: Path, option: str = "--out") -> Path:
    """`outputs.claim`, refused (exit 2) when the output is an input or another output."""
    from agent.outputs import OutputError

    try:
        return outputs.claim(path, option)
    except OutputError as exc:
        raise refused(str(exc)) from None


def identification_request(args: argparse.Namespace, paths, *, sampled_inputs: bool = False):
    """(config, request, settings) from the shared identification options; `sampled_inputs`:
    the records are the agent's own (`Settings.from_config`), not CSV records."""
    from agent.analysis import identify as identify_cmd
    from agent.channels import OUTPUT_ROLES
    from agent.config import MAX_DECIMATION
    from agent.ident.aircraft.airangles import Sources
    from agent.ident.settings import Settings

    if args.decimation is not None and args.decimation > MAX_DECIMATION:
        raise refused(f"--decimation {args.decimation}: give 1 to {MAX_DECIMATION}")
    config = load_optional_config(args.config).identification
    inputs, outputs = args.inputs, args.outputs
    if args.axes is not None:
        axis_inputs, axis_outputs = config.channels.axis_set(args.axes)
        inputs, outputs = inputs or axis_inputs, outputs or axis_outputs
    if not inputs or not outputs:
        raise refused("give --inputs and --outputs, or --axes lateral|longitudinal|full")
    trim_s = config.trim_seconds if args.trim is None else args.trim
    # The aircraft's states the outputs leave out, read where a record has them: their
    # kinematics (a lateral run's airspeed and θ).
    flight = {
        role: name
        for role in OUTPUT_ROLES
        if (name := getattr(config.channels, role)) not in outputs and name not in inputs
    }
    request = identify_cmd.Request(
        paths=tuple(paths),
        inputs=inputs,
        outputs=outputs,
        start=args.start,
        end=args.end,
        trim_seconds=trim_s,
        navigation=config.channels.navigation(),
        air_angles=Sources.of(config.channels, args.air_angles or config.air_angles),
        units=getattr(args, "units", None) or {},
        roles={
            n: role
            for n in (*inputs, *outputs, *config.channels.navigation(), *flight.values())
            if (role := config.channels.role_of(n) or _navigation_role(config.channels, n))
        },
        flight=flight,
    )
    settings = Settings.from_config(
        config,
        sampled_inputs=sampled_inputs,
        markov=args.markov,
        order=args.order,
        decimation=args.decimation,
        refine=args.refine,
        method=args.method,
        period_s=args.period,
        select=getattr(args, "select", False),
        closed_loop=getattr(args, "closed_loop", False),
    )
    return config, request, settings


def progress(total: int, quiet: bool):
    """A progress bar on stderr (tqdm) for long analyses; call with (None, None) to close."""
    if quiet or total < 2:
        return lambda done, of: None
    from tqdm import tqdm

    bar = tqdm(
        total=total, unit="id", file=sys.stderr, leave=False, disable=not sys.stderr.isatty()
    )

    def update(done, of):
        if done is None:
            bar.close()
        else:
            bar.n = done
            bar.refresh()

    return update


def run_cases(cases, args: argparse.Namespace, quiet: bool):
    """The identifications of `cases` (in processes, or on a Dask cluster), with a progress
    bar; refused without Dask, failed when the cluster cannot be reached."""
    from agent.analysis import analyze as an

    bar = progress(len(cases), quiet=quiet)
    try:
        return an.run_cases(cases, workers=args.jobs, scheduler=args.scheduler, progress=bar)
    except (OSError, ValueError, TimeoutError) as exc:  # a scheduler that cannot be reached
        raise failed(f"cannot run the jobs: {exc}") from None
    except ImportError as exc:  # --scheduler without Dask installed
        raise refused(f"--scheduler needs Dask ({exc}): pip install '.[cluster]'") from None
    finally:
        bar(None, None)
