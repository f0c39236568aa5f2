"""`sysid import`: an autopilot log (ArduPilot .bin, PX4 .ulg) as a record."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli import common


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "import",
        help="an autopilot log (ArduPilot .bin, PX4 .ulg) as a record for sysid identify",
        description="Map an ArduPilot DataFlash log to the channel names of `sysid identify` "
        "(attitude, rates, accelerations, airspeed, AoA/sideslip, surface outputs, SystemID "
        "records), uniformly resampled; see docs/post-flight.md for the mapping.",
    )
    parser.add_argument("file", type=Path, metavar="FILE", help="ArduPilot .bin or PX4 .ulg")
    parser.add_argument("--out", type=Path, required=True, help="CSV to write")
    parser.add_argument("--rate", type=float, default=50.0, help="sample rate of the record, Hz")
    parser.add_argument(
        "--config", type=Path, help="config.toml whose [excitation.surfaces] maps RC outputs"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from agent.analysis.importers import LogImportError, import_log

    config = common.load_optional_config(args.config)
    if not 1.0 <= args.rate <= 1000.0:
        raise common.refused(f"--rate {args.rate:g}: give 1 to 1000 Hz")
    outputs = common.outputs_for(
        {args.file: "the log being imported", **common.config_input(args.config)}
    )
    common.claim(outputs, args.out)
    try:
        imported = import_log(args.file, config.excitation.surfaces, args.rate)
        outputs.write_text(args.out, imported.csv())
    except LogImportError as exc:
        raise common.refused(str(exc)) from None
    except OSError as exc:
        raise common.failed(f"{args.out}: cannot be written ({exc.strerror or exc})") from None
    span = imported.time[-1] if len(imported.time) else 0.0
    print(
        f"{args.out}: {len(imported.time)} rows over {span:.1f} s at {args.rate:g} Hz; "
        f"columns {', '.join(imported.columns)}"
    )
    for note in imported.notes:
        print(f"note: {note}")
    if imported.missing:
        print(f"not in the log: {', '.join(imported.missing)}")
    return common.EXIT_OK
