"""`sysid analyze`: the onboard identification re-run on logs (per excitation, batch, sweeps,
cross-validation)."""

from __future__ import annotations

import argparse

from agent.cli import common


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "analyze",
        help="re-run the onboard identification on logs: per excitation, batch, sweeps, "
        "cross-validation",
        description="Re-run the agent's identification job on excitation logs (or any "
        "records) with changed settings (thesis 6.2.3).",
    )
    common.replay_options(parser)
    parser.add_argument("--batch", action="store_true", help="one identification of all")
    parser.add_argument(
        "--sweep", metavar="NAME=RANGE", help="markov=1:20 or order=2:12:2 or markov=1,2,5"
    )
    parser.add_argument(
        "--cross", action="store_true", help="each model on every other excitation (TIC_jN)"
    )
    parser.set_defaults(run=run)


def select(args: argparse.Namespace):
    """The logs `sysid analyze` and `sysid report` work on."""
    from agent.analysis import analyze as an

    try:
        return an.select_logs(args.data, args.excitation)
    except an.AnalyzeError as exc:
        raise common.refused(str(exc)) from None


def request_for(args: argparse.Namespace, paths):
    """`common.identification_request` for logs: where any of them is the agent's own, its
    inputs are the surfaces' sampled positions (`held_inputs = "auto"`: not held), as
    onboard."""
    from agent.analysis import analyze as an

    try:
        sampled = any(an.own_log(p) for p in paths)
    except an.AnalyzeError as exc:
        raise common.refused(str(exc)) from None
    return common.identification_request(args, paths, sampled_inputs=sampled)


def cases_for(args: argparse.Namespace, paths, batch: bool, sweep, prepared=None):
    """The cases of `sysid analyze` and `sysid report`: one identification per excitation
    (or one of all, or one per swept value); `prepared`: `request_for`'s answer when the
    caller has it."""
    from agent.analysis import analyze as an

    config, request, settings = prepared or request_for(args, paths)
    if getattr(args, "cross", False) and batch:
        raise common.refused("--cross needs one model per excitation: drop --batch")
    roles = [config.channels.role_of(n) for n in request.outputs]
    input_roles = [config.channels.role_of(n) for n in request.inputs]
    try:
        cases, _ = an.build_cases(
            request, roles, settings, batch=batch, sweep=sweep, input_roles=input_roles
        )
    except an.AnalyzeError as exc:
        raise common.refused(str(exc)) from None
    return cases


def run(args: argparse.Namespace) -> int:
    from agent.analysis import analyze as an
    from agent.analysis.findings import analysed

    paths = select(args)
    try:
        sweep = an.parse_sweep(args.sweep) if args.sweep else None
    except an.AnalyzeError as exc:
        raise common.refused(str(exc)) from None
    cases = cases_for(args, paths, args.batch, sweep)
    outcomes = common.run_cases(cases, args, quiet=args.json)
    analysis = analysed(
        paths,
        cases,
        outcomes,
        excitations=1 if args.batch else len(paths),
        sweep=sweep is not None,
        cross=args.cross,
    )
    if args.json:
        common.print_json(analysis.document())
    else:
        print(analysis.text())
    return common.EXIT_OK if any(o.ok for o in outcomes) else common.EXIT_FAILED
