"""`sysid export`: identified models (and data) to MATLAB .mat or JSON; derivatives to CSV."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agent.cli import common


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "export",
        help="identified models (and data) to MATLAB .mat or JSON; derivatives to CSV",
        description="Export the models of a result log, a model store file "
        "(models/<axes>_nominal.json), a ground log or a `sysid identify --json` result; "
        "variable names in docs/post-flight.md.",
    )
    parser.add_argument("source", type=Path, metavar="SOURCE")
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        help="FILE.mat or FILE.json (models), FILE.csv (derivatives with standard errors)",
    )
    parser.add_argument("--model", action="append", metavar="ID", help="only these model ids")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from agent.analysis.export import ExportError, load_models, to_csv, to_json, to_mat

    suffix = args.out.suffix.lower()
    if suffix not in (".mat", ".json", ".csv"):
        raise common.refused(f"{args.out}: give a .mat, .json or .csv file to write")
    inputs = {args.source: "the file being exported"}
    if args.source.suffix == ".json":  # a model store file: its data set is read with it
        inputs[args.source.with_suffix(".npz")] = "the exported model's data set"
    outputs = common.outputs_for(inputs)
    common.claim(outputs, args.out)
    try:
        models = load_models(args.source)
    except ExportError as exc:
        raise common.refused(str(exc)) from None
    if models.skipped:
        more = " …" if len(models.skipped) > 10 else ""
        lines = ", ".join(map(str, models.skipped[:10])) + more
        print(
            f"sysid export: warning: {args.source}: {len(models.skipped)} line(s) not JSON "
            f"and not exported (line {lines}); the rest is",
            file=sys.stderr,
        )
    if args.model:
        unknown = sorted(set(args.model) - {m["id"] for m in models})
        if unknown:
            raise common.refused(f"{args.source}: no model {', '.join(unknown)}")
        models = [m for m in models if m["id"] in args.model]
    try:
        if suffix == ".mat":
            with outputs.open(args.out) as handle:
                to_mat(models, handle)
        elif suffix == ".csv":
            outputs.write_text(args.out, to_csv(models))
        else:
            outputs.write_text(args.out, to_json(models))
    except ExportError as exc:
        raise common.refused(str(exc)) from None
    except OSError as exc:
        raise common.failed(f"{args.out}: cannot be written ({exc.strerror or exc})") from None
    print(f"{args.out}: {len(models)} model(s): {', '.join(m['id'] for m in models)}")
    return common.EXIT_OK
