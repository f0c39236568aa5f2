"""`sysid identify`: one linear model from CSV records."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli import common


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "identify",
        help="identify a linear model from CSV flight records (OKID/ERA)",
        description="Identify one linear model from one or more CSV records (a batch).",
    )
    parser.add_argument("data", nargs="+", type=Path, metavar="DATA.csv")
    common.identification_options(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from agent.analysis import identify as identify_cmd
    from agent.analysis.records import RecordError
    from agent.ident import DataError, IdentificationFailed
    from agent.ident.summary import format_text

    config, request, settings = common.identification_request(args, args.data)
    try:
        outcome = identify_cmd.run(request, config, settings)
    except (RecordError, DataError) as exc:
        raise common.CommandError(str(exc), common.EXIT_BAD_INPUT, "bad input") from None
    except IdentificationFailed as exc:
        raise common.CommandError(str(exc), common.EXIT_FAILED, "identification failed") from None
    if args.json:
        common.print_json(outcome.result.document(outcome.trim).model_dump(mode="json"))
    else:
        print(format_text(outcome.result, outcome.records, outcome.samples))
    return common.EXIT_OK
