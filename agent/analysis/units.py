"""Units of a foreign record's columns: declared in its header (`alpha [deg]`) or by `--units`,
converted to the unit each role is identified in (agent.channels.UNITS: surfaces in degrees,
angles and rates in radians, speeds in m/s), and a column without a declared unit checked
for values no aircraft flies in that unit ("these look like degrees").

A record from another system is as likely in degrees as in radians, and angles in degrees
read as radians make a model with spurious fast modes and no warning. The checks name only
what cannot be flight in the expected unit; a record in degrees whose every angle stays
below the limits (level flight's half degree) passes them, so the unit a user knows is best
declared.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping

import numpy as np

from agent.channels import UNITS

# Each unit a column may be declared in: (kind, its size in the kind's SI unit).
UNIT_SIZES: dict[str, tuple[str, float]] = {
    "rad": ("angle", 1.0),
    "deg": ("angle", math.pi / 180),
    "rad/s": ("rate", 1.0),
    "deg/s": ("rate", math.pi / 180),
    "m/s": ("speed", 1.0),
    "kt": ("speed", 1852 / 3600),
    "km/h": ("speed", 1 / 3.6),
    "ft/s": ("speed", 0.3048),
}
# The spellings a header or --units may use for a unit.
ALIASES = {
    "degree": "deg",
    "degrees": "deg",
    "°": "deg",
    "rad/sec": "rad/s",
    "deg/sec": "deg/s",
    "°/s": "deg/s",
    "kts": "kt",
    "knot": "kt",
    "knots": "kt",
    "kn": "kt",
    "kmh": "km/h",
    "fps": "ft/s",
    "mps": "m/s",
}
# A header's unit: the name, then the unit in square brackets or parentheses at its end.
HEADER_UNIT = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\[\]()]+)[\])]$")
# The largest magnitude each role's column may reach in its identified unit in any flight
# record: beyond it the values are no flight in that unit. α and β beyond 1 rad (57°) are
# post-stall; θ beyond π/2 is past the vertical; φ beyond π does not exist in radians; body
# rates beyond 10 rad/s (573°/s) are beyond an aerobatic aircraft's roll rate (about 7 rad/s);
# a heading beyond 2π is no heading in radians (0…2π or −π…π).
# A record in degrees crosses them with a cruise α of 2°, a bank of 4°, a roll rate of 11°/s.
PLAUSIBLE = {
    "alpha": 1.0,
    "beta": 1.0,
    "theta": math.pi / 2,
    "phi": math.pi,
    "p": 10.0,
    "q": 10.0,
    "r": 10.0,
    "psi": 2 * math.pi + 0.1,
}


class UnitError(ValueError):
    """A unit that cannot be read or applied; the message says which and why."""


# The time column's units, in seconds.
TIME_UNITS = {"s": 1.0, "sec": 1.0, "seconds": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}


def split_header(name: str) -> tuple[str, str | None]:
    """A header cell as (column name, declared unit or None): `alpha [deg]` → (alpha, deg),
    `time (ms)` → (time, ms). Only a unit known here (UNIT_SIZES, ALIASES, TIME_UNITS) is
    split off: `f(x)` stays a name."""
    match = HEADER_UNIT.match(name.strip())
    if match is None or not match["name"].strip():
        return name.strip(), None
    unit = match["unit"].strip()
    try:
        unit = canonical(unit)
    except UnitError:
        if unit.lower() not in TIME_UNITS:
            return name.strip(), None
        unit = unit.lower()
    return match["name"].strip(), unit


def canonical(unit: str) -> str:
    """The unit's own spelling (`degrees` → `deg`); a UnitError for a unit not known."""
    key = unit.strip()
    key = ALIASES.get(key.lower(), key.lower())
    if key not in UNIT_SIZES:
        raise UnitError(f"unit {unit!r} is not one of {', '.join(UNIT_SIZES)}")
    return key


def parse_units(text: str) -> dict[str, str]:
    """`--units alpha=deg,p=deg/s` → {column: unit}; a UnitError for a bad entry."""
    out = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        name, sep, unit = item.partition("=")
        if not sep or not name.strip() or not unit.strip():
            raise UnitError(f"--units takes NAME=UNIT,…; got {item!r}")
        out[name.strip()] = canonical(unit)
    return out


def converted(values: np.ndarray, name: str, unit: str, role: str | None) -> tuple[np.ndarray, str]:
    """`values` declared in `unit`, in the unit its role is identified in, with a note of what
    was done. A column without a role is taken to SI (its unit then says what it is); a unit
    of another kind than the role's (a speed for an angle) is a UnitError."""
    unit = canonical(unit)
    kind, size = UNIT_SIZES[unit]
    target = UNITS.get(role) if role else None
    if target is None or target not in UNIT_SIZES:
        target = next(u for u, (k, s) in UNIT_SIZES.items() if k == kind and s == 1.0)
    target_kind, target_size = UNIT_SIZES[target]
    if target_kind != kind:
        raise UnitError(
            f"column {name!r} is declared in {unit}, but its role {role} is {target_kind} "
            f"({target})"
        )
    if unit == target:
        return values, f"{name} in {unit}"
    return values * (size / target_size), f"{name} in {unit}, converted to {target}"


def implausible(values: np.ndarray, name: str, role: str | None) -> str | None:
    """Why a column with no declared unit cannot be in its role's unit, or None: a value no
    flight reaches there (PLAUSIBLE), which degrees for radians give."""
    limit = PLAUSIBLE.get(role or "")
    if limit is None or values.size == 0:
        return None
    peak = float(np.max(np.abs(values)))
    if peak <= limit:
        return None
    unit = UNITS[role]
    wanted = "deg/s" if unit == "rad/s" else "deg"
    return (
        f"column {name!r} ({role}) reaches {peak:.4g}; in {unit} no flight goes beyond "
        f"{limit:.3g}: these look like degrees; declare its unit in the header "
        f"('{name} [{wanted}]') or with --units {name}={wanted}"
    )


def declared_units(
    header_units: Mapping[str, str], given: Mapping[str, str], names
) -> dict[str, str]:
    """The unit of each of `names` that has one: --units (`given`) over the header's."""
    return {n: given.get(n, header_units.get(n)) for n in names if n in given or n in header_units}
