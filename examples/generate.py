"""Regenerate the bundled example flight records from the thesis's appendix A models.

    python examples/generate.py

Each record: 1 s of trimmed flight, then 30 s of orthogonal multisine excitation on every
input (0.05–2 Hz), at 50 Hz, in absolute units (trim + perturbation), with white sensor noise
at the levels of the thesis's instruments (table 3.1): VN-200 attitude 0.05° and rates
0.02 °/s RMS, µADC flow angles 0.2° and airspeed 0.1 m/s RMS.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from agent.ident import reference

DEG = np.pi / 180
SENSOR_NOISE = {
    "phi": 0.05 * DEG,
    "theta": 0.05 * DEG,
    "p": 0.02 * DEG,
    "q": 0.02 * DEG,
    "r": 0.02 * DEG,
    "alpha": 0.2 * DEG,
    "beta": 0.2 * DEG,
    "Vt": 0.1,
}
FILES = {"lateral": "a2_lateral.csv", "longitudinal": "a3_longitudinal.csv", "full": "a4_full.csv"}
# The share of the multisine each model is flown at: A.4's gains are large, and at the others'
# amplitudes its record reached 78 m/s from 17 and θ, φ and β of 3.7–4.7 rad, no flight (and
# `sysid identify` refuses such angles as degrees). At this share they stay within 0.3 rad.
SCALE = {"full": 0.08}


def write_csv(path: Path, record: reference.Record) -> None:
    columns = record.columns()
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        for k in range(record.time.size):
            writer.writerow([f"{columns[name][k]:.9g}" for name in columns])


def main() -> None:
    here = Path(__file__).parent
    for key, filename in FILES.items():
        model = reference.MODELS[key]
        inputs = SCALE.get(key, 1.0) * reference.multisine_inputs(
            model.inputs, 0.02, 30.0, 1, (0.05, 2.0)
        )
        record = reference.make_record(model, seed=1, noise=SENSOR_NOISE, inputs=inputs)
        write_csv(here / filename, record)
        print(f"wrote {here / filename} ({record.time.size} samples)")


if __name__ == "__main__":
    main()
