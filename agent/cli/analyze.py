"""`sysid analyze`: the onboard identification re-run on logs (per excitation, batch, sweeps,
cross-validation)."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli.common import (
    EXIT_FAILED,
    EXIT_OK,
    identification_request,
    print_json,
    refused,
    replay_options,
    run_cases,
)


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "analyze",
        help="re-run the onboard identification on logs: per excitation, batch, sweeps, "
        "cross-validation",
        description="Re-run the agent's identification job on excitation logs (or any "
        "records) with changed settings (thesis 6.2.3).",
    )
    replay_options(parser)
    parser.add_argument("--batch", action="store_true", help="one identification of all")
    parser.add_argument("--sweep", metavar="NAME=RANGE",
                        help="markov=1:20 or order=2:12:2 or markov=1,2,5")  # fmt: skip
    parser.add_argument("--cross", action="store_true",
                        help="each model on every other excitation (TIC_jN)")  # fmt: skip
    parser.set_defaults(run=run)


def select(args: argparse.Namespace):
    """The logs `sysid analyze` and `sysid report` work on."""
    from agent.analysis import analyze as an

    try:
        return an.select_logs(args.data, args.excitation)
    except an.AnalyzeError as exc:
        raise refused(str(exc)) from None


def cases_for(args: argparse.Namespace, paths, batch: bool, sweep, prepared=None):
    """The cases of `sysid analyze` and `sysid report`: one identification per excitation
    (or one of all, or one per swept value); `prepared`: `identification_request`'s answer
    when the caller has it."""
    from agent.analysis import analyze as an

    config, request, settings = prepared or identification_request(args, paths)
    if getattr(args, "cross", False) and batch:
        raise refused("--cross needs one model per excitation: drop --batch")
    roles = [config.channels.role_of(n) for n in request.outputs]
    input_roles = [config.channels.role_of(n) for n in request.inputs]
    try:
        cases, _ = an.build_cases(request, roles, settings, batch=batch, sweep=sweep,
                                  input_roles=input_roles)  # fmt: skip
    except an.AnalyzeError as exc:
        raise refused(str(exc)) from None
    return cases


def run(args: argparse.Namespace) -> int:
    from agent.analysis import analyze as an

    paths = select(args)
    try:
        sweep = an.parse_sweep(args.sweep) if args.sweep else None
    except an.AnalyzeError as exc:
        raise refused(str(exc)) from None
    cases = cases_for(args, paths, args.batch, sweep)
    outcomes = run_cases(cases, args, quiet=args.json)
    report = {"logs": [str(p) for p in paths], "cases": [
        {"excitation": c.label, "setting": dict(c.key), **case_summary(o)}
        for c, o in zip(cases, outcomes, strict=True)]}  # fmt: skip
    excitations = 1 if args.batch else len(paths)
    if sweep is not None:
        table = an.sweep_table(cases, outcomes)
        report["sweep"] = table
        report["recommended"] = an.recommend(table, excitations)
    if args.cross:
        report["cross_tic"] = an.cross_validation(cases, outcomes)
    if args.json:
        print_json(report)
    else:
        print(analysis_text(report, paths))
    return EXIT_OK if any(o["ok"] for o in outcomes) else EXIT_FAILED


def case_summary(outcome: dict) -> dict:
    if not outcome["ok"]:
        return {"ok": False, "reason": outcome["reason"]}
    r = outcome["result"]
    modes = [{"name": m["name"], "eigenvalue": m["eigenvalue"]} for m in r["modes"]]
    refinement = r.get("refinement")
    return {"ok": True, "markov": r["markov"], "order": r["order"], "tic_avg": r["tic_avg"],
            "modes": modes, "converged": refinement["converged"] if refinement else None,
            "warnings": list(r.get("warnings", ()))}  # fmt: skip


def analysis_text(report: dict, paths) -> str:
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
