"""The µADC driver: lines → true airspeed, α, β (rad) with probe-limit flags, altitude."""

from __future__ import annotations

import math
from collections.abc import Callable

from drivers.airdata.codec import SAMPLE_WRAP, AirData, AirDataCodec
from drivers.config import AirDataPort, Sensors
from drivers.sensor import Reading, Sample, SensorDriver
from drivers.serialio import Backoff
from drivers.timing import Unwrap
from drivers.values import Clock

DEG = math.pi / 180
# ISA sea level and troposphere (ICAO Doc 7488).
RHO0, T0, LAPSE, R_AIR = 1.225, 288.15, 0.0065, 287.053
# A reading this close to the probe's range is at the stop: flagged as clipped.
CLIP_MARGIN_DEG = 0.05


def true_airspeed(ias: float, static_pa: float, pressure_altitude: float) -> float:
    """TAS = IAS·√(ρ₀/ρ), ρ from static pressure and the ISA temperature at the pressure
    altitude (the µADC carries no temperature: the ISA assumption is stated in docs/sensors.md)."""
    temperature = T0 - LAPSE * pressure_altitude
    rho = static_pa / (R_AIR * temperature)
    return ias * math.sqrt(RHO0 / rho)


class AirDataConverter:
    """Stateful: unwraps the five-digit sample counter into device time."""

    def __init__(self, cfg: AirDataPort):
        self._cfg = cfg
        self._unwrap = Unwrap(SAMPLE_WRAP)

    def reset(self) -> None:
        self._unwrap.reset()

    def __call__(self, m: AirData) -> Reading | None:
        limit = self._cfg.probe_limit_deg - CLIP_MARGIN_DEG
        if m.p_static <= 0 or not math.isfinite(m.ias):
            return None
        vanes = self._cfg.vanes  # without them the fields carry nothing: recorded missing
        values = {
            "ias": m.ias,
            "Vt": true_airspeed(m.ias, m.p_static, m.altitude),
            "alpha": m.alpha_deg * DEG if vanes else math.nan,
            "beta": m.beta_deg * DEG if vanes else math.nan,
            "alpha_clipped": float(vanes and abs(m.alpha_deg) >= limit),
            "beta_clipped": float(vanes and abs(m.beta_deg) >= limit),
            "alt_pressure": m.altitude,
            "p_total": m.p_total,
            "p_static": m.p_static,
        }
        sample = self._unwrap(m.sample)
        values["adc_sample"] = float(sample)
        return Reading(sample / self._cfg.rate_hz, values)


def make_driver(sensors: Sensors, clock: Clock, publish: Callable[[Sample], None]) -> SensorDriver:
    cfg = sensors.airdata
    convert = AirDataConverter(cfg)
    backoff = Backoff(sensors.backoff_initial_s, sensors.backoff_max_s)
    return SensorDriver(
        "airdata", cfg, backoff, AirDataCodec(), convert, publish, clock, on_reconnect=convert.reset
    )
