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
    common.aircraft_arguments(parser)
    parser.add_argument(
        "--list-aircraft",
        action="store_true",
        help="list the JSBSim aircraft it can fly, with the speeds the benchmark's six are "
        "flown at, and exit",
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

    if args.list_aircraft:
        return _list_aircraft(args.json)
    progress = None if args.json else (lambda text: print(text, flush=True))
    options = SimOptions(
        plane=common.aircraft_options(args),
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


def _list_aircraft(as_json: bool) -> int:
    """`sysid sim --list-aircraft`: the aircraft JSBSim holds, the benchmark's with their
    trim speed and height."""
    from agent.sim.aircraft import FLOWN, jsbsim_aircraft

    names = jsbsim_aircraft()
    if as_json:
        flown = {n: {"speed_kts": v, "altitude_ft": h, "kind": k} for n, (v, h, k) in FLOWN.items()}
        common.print_json({"aircraft": names, "benchmark": flown})
        return common.EXIT_OK
    print("flown by the benchmark (sysid sim --aircraft NAME flies it at this speed):")
    for name, (speed, height, kind) in FLOWN.items():
        print(f"  {name:10} {speed:5.0f} kt  {height:5.0f} ft  {kind}")
    others = [n for n in names if n not in FLOWN]
    print(f"also in JSBSim ({len(others)}; give --speed-kts, and expect no trim for some):")
    print("  " + ", ".join(others))
    return common.EXIT_OK
