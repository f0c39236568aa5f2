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
    parser.add_argument(
        "--validate",
        action="append",
        type=Path,
        default=[],
        metavar="FILE.csv",
        help="a held-out record (a repeat manoeuvre) the model is then scored on: its TIC with "
        "the record's initial state and output biases estimated, and from its trim; repeat "
        "for more",
    )
    common.identification_options(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from agent.analysis import identify as identify_cmd
    from agent.analysis.records import RecordError
    from agent.ident import DataError, IdentificationFailed
    from agent.ident.summary import format_text

    config, request, settings = common.identification_request(args, args.data)
    try:
        outcome = identify_cmd.run(request, config, settings, validate=args.validate)
    except (RecordError, DataError) as exc:
        raise common.CommandError(str(exc), common.EXIT_BAD_INPUT, "bad input") from None
    except IdentificationFailed as exc:
        raise common.CommandError(str(exc), common.EXIT_FAILED, "identification failed") from None
    if args.json:
        common.print_json(outcome.document().model_dump(mode="json"))
    else:
        print(format_text(outcome.result, outcome.records, outcome.samples))
        print(validation_lines(outcome))
    return common.EXIT_OK


def validation_lines(outcome) -> str:
    """The validation scores below the summary: the model's own records with their initial
    state and output biases estimated, and the held-out records' (--validate)."""
    doc = outcome.document()

    def tics(values: dict[str, float]) -> str:
        return "  ".join(f"{n} {v:.3f}" for n, v in values.items())

    lines = []
    if doc.tic_validation is not None:
        mean = sum(doc.tic_validation.values()) / len(doc.tic_validation)
        lines.append(
            f"TIC with each record's initial state and output biases estimated (as a "
            f"validation scores it): {tics(doc.tic_validation)}  (average {mean:.3f})"
        )
    if doc.validation is not None:
        v = doc.validation
        lines += [
            f"validation on {', '.join(v.files)} (initial state and output biases estimated): "
            f"{tics(v.tic)}  (average {v.tic_avg:.3f})",
            f"  from its trim (x(0) = 0, no biases): {tics(v.tic_from_trim)}  "
            f"(average {v.tic_from_trim_avg:.3f})",
        ]
    return "\n".join(lines)
