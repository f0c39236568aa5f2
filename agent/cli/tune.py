"""`sysid tune`: ArduPlane's roll and pitch gains designed from an identified model."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from agent.cli import common


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "tune",
        help="ArduPlane roll and pitch gains designed from an identified model",
        description="Design ArduPlane's FBWA roll and pitch gains (RLL_RATE_*, PTCH_RATE_*, "
        "*2SRV_TCONST) from an identified model by loop shaping on it with its servo lag and "
        "delay, print the predicted margins, crossover, disturbance rejection and step "
        "response, and write them as an ArduPilot .param file (docs/tuning.md).",
    )
    parser.add_argument(
        "model",
        type=Path,
        metavar="MODEL",
        help="a `sysid identify --json` result, a model store file or a result log",
    )
    parser.add_argument("--model-id", metavar="ID", help="the model of a log or store to tune")
    parser.add_argument(
        "--config", type=Path, help="the agent's config: its surfaces' PWM mapping and channels"
    )
    parser.add_argument(
        "--linkage",
        type=_gains,
        default={},
        metavar="SURFACE=GAIN,…",
        help="measured surface per commanded degree (the run's 'follows' check), default 1",
    )
    parser.add_argument(
        "--exec-log",
        type=Path,
        metavar="FILE",
        help="an agent's execution log: each surface's linkage and lag as its last run measured "
        "them (--linkage, --servo-lag and --delay given win)",
    )
    parser.add_argument(
        "--servo-lag",
        type=float,
        metavar="S",
        help="servo time constant, s (0.05; 0 with --exec-log)",
    )
    parser.add_argument(
        "--delay",
        type=float,
        metavar="S",
        help="servo dead time, s (0.02; with --exec-log, the lag the run measured)",
    )
    parser.add_argument("--roll-tconst", type=float, metavar="S", help="target RLL2SRV_TCONST")
    parser.add_argument("--pitch-tconst", type=float, metavar="S", help="target PTCH2SRV_TCONST")
    parser.add_argument(
        "--scaling-speed",
        type=float,
        metavar="M/S",
        help="the aircraft's SCALING_SPEED (default: the model's trim airspeed)",
    )
    parser.add_argument("--out", type=Path, metavar="FILE.param", help="write the gains here")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from agent.analysis.export import ExportError, load_models
    from agent.fbwa import DEFAULTS
    from agent.tune import TCONST_RANGE, Model, Options, TuneError, design, param_file

    inputs = {args.model: "the model being tuned", **common.config_input(args.config)}
    if args.exec_log is not None:
        inputs[args.exec_log] = "the execution log"
    outputs = common.outputs_for(inputs)
    if args.out is not None:
        common.claim(outputs, args.out)
        if args.out.suffix != ".param":
            raise common.refused(f"{args.out}: give a .param file to write")
    for option, value in (("--servo-lag", args.servo_lag), ("--delay", args.delay)):
        if value is not None and not 0 <= value <= 1:
            raise common.refused(f"{option} {value:g}: seconds between 0 and 1")
    measured, unusable = {}, []
    if args.exec_log is not None:
        measured, unusable = _measured_linkage(args.exec_log)
    for option, value in (
        ("--roll-tconst", args.roll_tconst),
        ("--pitch-tconst", args.pitch_tconst),
    ):
        if value is not None and not TCONST_RANGE[0] <= value <= TCONST_RANGE[1]:
            raise common.refused(
                f"{option} {value:g}: ArduPlane's time constants here are "
                f"{TCONST_RANGE[0]:g}–{TCONST_RANGE[1]:g} s"
            )
    if args.scaling_speed is not None and not 1.0 <= args.scaling_speed <= 200.0:
        raise common.refused(f"--scaling-speed {args.scaling_speed:g}: m/s between 1 and 200")
    config = common.load_optional_config(args.config)
    try:
        models = load_models(args.model)
    except ExportError as exc:
        raise common.refused(str(exc)) from None
    if args.model_id is not None:
        models = [m for m in models if m["id"] == args.model_id]
        if not models:
            raise common.refused(f"{args.model}: no model {args.model_id}")
    if not models:
        raise common.refused(f"{args.model}: no model in it")
    model = models[-1]
    if model["Ac"].size == 0:
        raise common.refused(f"{model['id']}: no continuous-time model to design on")
    trim = dict(zip(model["outputs"], model["y0"], strict=False)) if model["y0"].size else {}
    if args.scaling_speed is None and config.identification.channels.airspeed not in trim:
        raise common.refused(f"{model['id']}: the model has no trim airspeed: give --scaling-speed")
    options = Options(
        linkage=args.linkage,
        measured=measured,
        servo_lag_s=args.servo_lag,
        delay_s=args.delay,
        roll_tconst=args.roll_tconst,
        pitch_tconst=args.pitch_tconst,
        scaling_speed=args.scaling_speed,
    )
    subject = Model(
        id=model["id"],
        inputs=list(model["inputs"]),
        outputs=list(model["outputs"]),
        A=model["Ac"],
        B=model["Bc"],
        C=model["Cc"],
        trim=trim,
    )
    try:
        designed = design(
            subject, config.identification.channels, config.excitation.surfaces, options
        )
    except TuneError as exc:
        raise common.failed(str(exc)) from None
    tunes, refused, notes = designed.tunes, designed.refused, (*unusable, *designed.notes)
    eas, scaling = designed.eas, designed.scaling_speed
    yaw = designed.yaw
    setup_params = {**(yaw.params if yaw is not None else {}), "SCALING_SPEED": round(scaling, 1)}
    if args.out is not None:
        header = [
            f"sysid tune {args.model.name} ({model['id']}): ArduPlane FBWA gains",
            f"SCALING_SPEED {scaling:.1f} m/s; linkage and servo from "
            f"{args.exec_log.name if args.exec_log else 'the options'}",
        ]
        text = param_file(tunes, header) + "".join(f"{k},{v:g}\n" for k, v in setup_params.items())
        try:
            outputs.write_text(args.out, text)
        except OSError as exc:
            raise common.failed(f"{args.out}: cannot be written ({exc.strerror or exc})") from None
    if args.json:
        common.print_json(
            {
                "model": model["id"],
                "scaling_speed": scaling,
                "axes": [_as_json(t, DEFAULTS) for t in tunes],
                "yaw": None if yaw is None else _yaw_json(yaw),
                "refused": refused,
                "notes": notes,
                "measured_linkage": measured,
                "param_file": None if args.out is None else str(args.out),
            }
        )
        return common.EXIT_OK
    print(f"{model['id']}: ArduPlane FBWA gains at {eas:.1f} m/s (SCALING_SPEED {scaling:.1f})")
    for note in notes:
        print(f"note: {note}")
    for surface, m in measured.items():
        each_way = ""
        if m.get("even"):
            up, down = m["gain"] + m["even"], m["gain"] - m["even"]
            each_way = f" ({down:.3g} below {m['knee']:.3g}°, {up:.3g} above)"
        print(
            f"{surface}: linkage {m['gain']:.3g}{each_way} and lag {m['lag_s']:.3f} s as the run "
            f"measured them ({args.exec_log.name})"
        )
    for t in tunes:
        print(f"\n{t.axis}:")
        for name, value in t.params.items():
            print(f"  {name:<16} {value:>8.4g}   (ArduPlane's default {DEFAULTS[name]:g})")
        r, a = t.rate_loop, t.attitude_loop
        print(
            f"  rate loop: crossover {r.crossover_rad_s:.2f} rad/s, phase margin "
            f"{r.phase_deg:.0f}°, gain margin {_db(r.gain_db)}"
        )
        print(
            f"  whole loop: crossover {a.crossover_rad_s:.2f} rad/s, phase margin "
            f"{a.phase_deg:.0f}°, gain margin {_db(a.gain_db)}, disturbance rejection to "
            f"{a.rejection_rad_s:.2f} rad/s"
            if a.rejection_rad_s is not None
            else ""
        )
        if t.down is None:
            print(
                f"  a {t.step_deg:g}° step: rise (10–90 %) {t.rise_s:.2f} s, overshoot "
                f"{t.overshoot_pct:.1f} %"
            )
        else:  # the linkage moves the surface more one way: each way its own
            for sign, (rise, overshoot) in t.each_way().items():
                print(
                    f"  a {sign}{t.step_deg:g}° step: rise (10–90 %) {rise:.2f} s, overshoot "
                    f"{overshoot:.1f} %"
                )
        for note in t.notes:
            print(f"  note: {note}")
    if yaw is not None:
        before, after = yaw.before, yaw.after
        print("\nyaw damper:")
        for name, value in yaw.params.items():
            print(f"  {name:<16} {value:>8.4g}   (ArduPlane's default {DEFAULTS[name]:g}: off)")
        print(
            f"  Dutch roll with the roll loop closed: ζ {yaw.zeta(before):.2f} at "
            f"{abs(before):.2f} rad/s without, ζ {yaw.zeta(after):.2f} at {abs(after):.2f} rad/s "
            f"with; the damper's gain margin {_db(yaw.gain_margin_db)}"
        )
        for note in yaw.notes:
            print(f"  note: {note}")
    for why in refused:
        print(f"not tuned: {why}")
    if args.out is not None:
        print(f"\n{args.out}: written (load it in the ground station, or let the agent apply it)")
    return common.EXIT_OK


def _measured_linkage(path: Path) -> tuple[dict[str, dict[str, float]], list[str]]:
    """Each surface's linkage gain, its even part and lag from the last linkage line of an
    execution log (agent.logs.Logbook.linkage), and why any surface's there is not used;
    refused when it has none, or none usable."""
    import json

    found = None
    try:
        with path.open("rb") as handle:
            for raw in handle:
                try:
                    event = json.loads(raw)
                except ValueError:
                    continue  # a line cut by a crash: the log is crash-safe line by line
                linkage = event.get("linkage") if isinstance(event, dict) else None
                if isinstance(linkage, dict) and linkage:  # a run where nothing followed: none
                    found = linkage
    except OSError as exc:
        raise common.refused(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if not found:
        raise common.refused(f"{path}: no run's linkage in it (a finished excitation logs one)")
    measured, unusable = {}, []
    for surface, values in found.items():
        try:
            gain, lag = float(values["gain"]), float(values["lag_s"])
            # Logs from before these were measured have neither: a straight linkage.
            even = float(values.get("even", 0.0))
            knee = float(values.get("knee", 0.0))
        except (AttributeError, KeyError, TypeError, ValueError):
            unusable.append(f"{surface}: the log's linkage is not numbers: not used")
            continue
        # A linkage that moves the surface, each way, within a second's lag.
        if gain > 0 and abs(even) < gain and 0 <= lag <= 1 and math.isfinite(knee):
            measured[surface] = {"gain": gain, "lag_s": lag, "even": even, "knee": knee}
        else:
            unusable.append(
                f"{surface}: the log's linkage (gain {gain:.3g}, even part {even:.3g}, knee "
                f"{knee:.3g}, lag {lag:.3g} s) is not one that moves the surface both ways, "
                "from a finite knee, within a second: not used"
            )
    if not measured:
        raise common.refused(f"{path}: no usable linkage in it ({'; '.join(unusable)})")
    return measured, unusable


def _gains(text: str) -> dict[str, float]:
    """SURFACE=GAIN,… (a gain a positive number)."""
    gains = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        name, sep, value = part.partition("=")
        try:
            gain = float(value)
        except ValueError:
            gain = float("nan")
        if not sep or not name.strip() or not 0 < gain < 100:
            raise argparse.ArgumentTypeError(
                f"{part!r}: give SURFACE=GAIN with a positive gain (aileron=0.8)"
            )
        gains[name.strip()] = gain
    return gains


def _db(value: float) -> str:
    return "∞ (the phase never reaches −180°)" if value == float("inf") else f"{value:.1f} dB"


def _yaw_json(yaw) -> dict:
    def mode(value: complex) -> dict:
        return {"eigenvalue": [value.real, value.imag], "damping": yaw.zeta(value)}

    return {
        "params": yaw.params,
        "dutch_roll_without": mode(yaw.before),
        "dutch_roll_with": mode(yaw.after),
        "gain_margin_db": None if yaw.gain_margin_db == float("inf") else yaw.gain_margin_db,
        "notes": list(yaw.notes),
    }


def _as_json(t, defaults) -> dict:
    def margins(m):
        return {
            "crossover_rad_s": m.crossover_rad_s,
            "phase_margin_deg": m.phase_deg,
            "gain_margin_db": None if m.gain_db == float("inf") else m.gain_db,
            "rejection_rad_s": m.rejection_rad_s,
        }

    return {
        "axis": t.axis,
        "params": t.params,
        "defaults": {k: defaults[k] for k in t.params},
        "rate_loop": margins(t.rate_loop),
        "whole_loop": margins(t.attitude_loop),
        "step_deg": t.step_deg,
        "rise_s": t.rise_s,
        "overshoot_pct": t.overshoot_pct,
        "each_way": {
            sign: {"rise_s": rise, "overshoot_pct": overshoot}
            for sign, (rise, overshoot) in zip(("+", "-"), t.each_way().values(), strict=True)
        },
        "notes": list(t.notes),
    }
