"""`sysid sim`: a whole flight with no hardware, end to end."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli import common
from agent.excitation.names import PRESETS

# With sizing and no --runs: runs until the operator accepts a model, at most this many (the
# build-up, then sized runs that grow at most 2× each, so the fourth reaches any plan's own
# amplitudes from a quarter).
SIZED_RUNS = 4


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "sim",
        help="a whole flight with no hardware, end to end",
        description="Simulated aircraft, emulated ArduPlane, sensors and "
        "radios, the real agent, and a scripted ground operator.",
    )
    parser.add_argument("--aircraft", default="J3Cub")
    parser.add_argument("--speed-kts", type=float, default=60.0)
    parser.add_argument(
        "--altitude-ft",
        type=float,
        default=1000.0,
        help="height above the ground to trim at (a glider sinks all flight: start high)",
    )
    parser.add_argument(
        "--turbulence",
        type=common.turbulence,
        default=0.0,
        help="Dryden intensity: 0 none, 1 light (W20 = 5 ft/s), at most 15 (severe)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--no-vanes",
        action="store_true",
        help="air data with the airspeed only (no α, β vanes): the agent synthesises α and β "
        "from the INS",
    )
    parser.add_argument("--preset", choices=PRESETS, default="full")
    parser.add_argument(
        "--runs",
        type=common.positive_int,
        default=None,
        help="excitations in a row (from the second on: TIC against the nominal); default "
        "with sizing: until the operator accepts a model, at most 4 (the build-up run, then "
        "sized runs); 1 without",
    )
    parser.add_argument(
        "--sizing",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the operator has each plan sized by the aircraft before arming it (default); "
        "--no-sizing arms the preset at its own amplitudes",
    )
    parser.add_argument("--keep", type=Path, metavar="DIR", help="keep logs and models in DIR")
    parser.add_argument("--json", action="store_true", help="one JSON object")
    parser.add_argument(
        "--interactive",
        action="store_true",
        help="fly it from the ground console instead of the script (the simulated pilot "
        "flips the switch 2 s after a plan is armed)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from agent.sim.flight import SimError, SimOptions, fly, format_report, interactive
    from agent.sim.plant import PlantError

    progress = None if args.json else (lambda text: print(text, flush=True))
    options = SimOptions(
        plane=common.aircraft_options(args, altitude_ft=args.altitude_ft),
        preset=args.preset,
        runs=args.runs or (SIZED_RUNS if args.sizing else 1),
        sizing=args.sizing,
        until_accepted=args.sizing and args.runs is None,
        directory=args.keep,
        progress=progress,
    )
    if args.interactive:
        try:
            asyncio.run(interactive(options))
        except (PlantError, SimError) as exc:
            raise common.failed(str(exc)) from None
        return common.EXIT_OK
    try:
        report = asyncio.run(fly(options))
    except (PlantError, SimError) as exc:
        code = common.EXIT_BAD_INPUT if isinstance(exc, PlantError) else common.EXIT_FAILED
        raise common.CommandError(str(exc), code) from None
    if args.json:
        common.print_json(report)
    else:
        print(format_report(report))
    return common.EXIT_OK if not report["failure"] else common.EXIT_FAILED
