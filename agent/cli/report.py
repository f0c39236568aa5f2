"""`sysid report`: an HTML report with figures for excitation logs."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli import common
from agent.cli.analyze import cases_for, request_for, select


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "report",
        help="an HTML report with figures for excitation logs",
        description="Time histories against the identified models with TIC, eigenvalues in "
        "the s-plane, Hankel singular values, Bode plots against the data, input spectra "
        "and RPF, mode tables, and ArduPlane gains designed from each model with their "
        "loops' Bode plots and predicted steps.",
    )
    common.replay_options(parser)
    parser.add_argument("--out", type=Path, required=True, metavar="DIR")
    parser.add_argument(
        "--nominal", type=Path, metavar="MODEL.json", help="a model store file to highlight"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    paths = select(args)
    prepared = request_for(args, paths)
    nominal = None
    if args.nominal is not None:
        from agent.models import model_summary

        try:
            nominal = model_summary(args.nominal)
        except ValueError as exc:
            raise common.refused(str(exc)) from None
    cases = cases_for(args, paths, batch=False, sweep=None, prepared=prepared)
    from agent.analysis.report import files, write

    inputs = {path: "a log being reported" for path in paths}
    inputs |= {args.nominal: "the nominal model", **common.config_input(args.config)}
    outputs = common.outputs_for(inputs)
    config = common.load_optional_config(args.config)
    for path in files(args.out, cases):  # refused before the identifications run
        common.claim(outputs, path)
    outcomes = common.run_cases(cases, args, quiet=False)
    try:
        page = write(args.out, paths, cases, outcomes, nominal, outputs, config)
    except OSError as exc:
        raise common.failed(f"{args.out}: cannot be written ({exc.strerror or exc})") from None
    identified = sum(o.ok for o in outcomes)
    if args.json:
        common.print_json(
            {"page": str(page), "identified": identified, "excitations": len(outcomes)}
        )
    else:
        print(f"{page}: {identified} of {len(outcomes)} excitation(s) identified")
    return common.EXIT_OK if any(o.ok for o in outcomes) else common.EXIT_FAILED
