"""The surface-box driver: counts → surface degrees (per-channel calibration), ganged
aileron, elevator and flap (thesis eq. 3.1), rudder, and engine RPM."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from drivers.config import Calibration, Sensors, SurfacePort
from drivers.sensor import Reading, Sample, SensorDriver
from drivers.serialio import Backoff
from drivers.surfaces.codec import CHANNELS, SurfaceCodec, SurfaceFrame
from drivers.timing import Unwrap
from drivers.values import Clock


def counts_to_degrees(counts: float, calibration: Calibration) -> float:
    """One potentiometer: table (linear between points, held beyond) or polynomial
    (coefficients lowest order first, evaluated by Horner's rule in plain Python: seven of
    these run on the event loop for every frame, and numpy's polyval on one number costs five
    times as much)."""
    if calibration.table is not None:
        points = np.asarray(calibration.table, dtype=float)
        return float(np.interp(counts, points[:, 0], points[:, 1]))
    value = 0.0
    for coefficient in reversed(calibration.poly):
        value = value * counts + coefficient
    return float(value)


def gang(surfaces: Mapping[str, float]) -> dict[str, float]:
    """δA = ½(δA_R − δA_L), δE = ½(δE_L + δE_R) (eq. 3.1); flaps symmetric, ½(L + R)."""
    return {
        "aileron": 0.5 * (surfaces["aileron_right"] - surfaces["aileron_left"]),
        "elevator": 0.5 * (surfaces["elevator_left"] + surfaces["elevator_right"]),
        "rudder": surfaces["rudder"],
        "flap": 0.5 * (surfaces["flap_left"] + surfaces["flap_right"]),
    }


class SurfaceConverter:
    """Stateful: unwraps the Arduino's millis into device time."""

    def __init__(self, cfg: SurfacePort):
        self._cfg = cfg
        self._unwrap = Unwrap(1 << 32)

    def reset(self) -> None:
        self._unwrap.reset()

    def __call__(self, frame: SurfaceFrame) -> Reading:
        each = {
            name: counts_to_degrees(c, self._cfg.calibration[name])
            for name, c in zip(CHANNELS, frame.counts, strict=True)
        }
        values = {**each, **gang(each), "rpm": float(frame.rpm), "box_seq": float(frame.seq)}
        return Reading(self._unwrap(frame.millis) / 1000.0, values)


def make_driver(sensors: Sensors, clock: Clock, publish: Callable[[Sample], None]) -> SensorDriver:
    cfg = sensors.surfaces
    convert = SurfaceConverter(cfg)
    backoff = Backoff(sensors.backoff_initial_s, sensors.backoff_max_s)
    return SensorDriver(
        "surfaces",
        cfg,
        backoff,
        SurfaceCodec(),
        convert,
        publish,
        clock,
        on_reconnect=convert.reset,
    )
