"""`sysid excite`: an excitation plan previewed before flight."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agent.cli import common
from agent.excitation.names import PRESETS


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "excite",
        help="preview an excitation plan before flight",
        description="Render a plan at the command rate: CSV (default), a JSON summary, a plot.",
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--preset", choices=PRESETS, help="one of the thesis's plans")
    source.add_argument("--plan", type=Path, metavar="PLAN.json", help="a plan file")
    parser.add_argument("--rate", type=float, metavar="HZ", help="command rate (default: config)")
    parser.add_argument(
        "--amplitude",
        action="append",
        default=[],
        metavar="CONTROL=VALUE",
        help="preset amplitude (deg, throttle %%) from trim; repeat per control",
    )
    parser.add_argument("--csv", action="store_true", help="time and one column per control")
    parser.add_argument("--json", action="store_true", help="duration, RPF, peak, band, warnings")
    parser.add_argument("--plot", type=Path, metavar="FILE.png", help="draw the plan")
    parser.add_argument("--config", type=Path, help="config file (default ./config.toml if any)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from agent.excitation import plan as plans
    from agent.excitation.preview import PreviewError, csv_text, load_plan, parse_amplitudes, plot

    config = common.load_optional_config(args.config)
    outputs = common.outputs_for({args.plan: "the plan", **common.config_input(args.config)})
    plot_path = None
    if args.plot is not None:  # matplotlib writes a name without a suffix as name.png
        plot_path = args.plot if args.plot.suffix else args.plot.with_name(args.plot.name + ".png")
        common.claim(outputs, plot_path, "--plot")
    try:
        rate = config.excitation.rate_hz if args.rate is None else args.rate
        if not 1.0 <= rate <= 1000.0:
            raise PreviewError(f"--rate must be within 1–1000 Hz, got {rate:g}")
        if args.plan is not None:
            plan = load_plan(args.plan)
        else:
            plan = plans.preset(args.preset, parse_amplitudes(args.amplitude))
        timeline = plans.check(plan, rate, config.excitation.surfaces, config.excitation.envelope)
    except (PreviewError, plans.PlanRefused, ValueError) as exc:
        raise common.refused(str(exc)) from None
    columns = {n: getattr(config.identification.channels, n) for n in timeline.values}
    report = plans.summary(timeline, config.excitation.surfaces)
    for warning in report["warnings"]:
        print(f"sysid excite: warning: {warning}", file=sys.stderr)
    if plot_path is not None:
        try:
            plot(timeline, report, columns, plot_path, outputs)
        except ValueError as exc:  # PreviewError, or matplotlib's unknown file format
            raise common.refused(str(exc)) from None
    if args.json:
        common.print_json(report)
    elif args.csv or args.plot is None:
        sys.stdout.write(csv_text(timeline, columns))
    return common.EXIT_OK
