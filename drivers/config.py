"""The devices' sections of the configuration (pydantic, extra="forbid", frozen): the serial
ports, the surface box's calibration, the autopilot link. `agent.config` composes them into
the whole file; they live here so that the drivers depend on nothing above them."""

from __future__ import annotations

import itertools
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from drivers.surfaces.codec import CHANNELS
from drivers.vectornav.codec import field_names


class Section(BaseModel):
    """A section of a config file: unknown keys, inf and nan refused; frozen; each field's
    docstring is its description."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        use_attribute_docstrings=True,
        allow_inf_nan=False,
    )


class SerialPort(Section):
    """A serial port and how the driver keeps it alive."""

    port: str = Field(min_length=1)
    """Device path (prefer a stable /dev/serial/by-id/... link) or a pyserial URL."""
    baud: int = Field(115200, ge=1200, le=4_000_000)
    """Baud rate (irrelevant on pseudo-terminals)."""
    rate_hz: float = Field(100.0, gt=0.0, le=1000.0)
    """The device's output rate: gaps and the expected sample period follow from it."""
    silence_s: float = Field(1.0, gt=0.0, le=60.0)
    """No byte for this long counts as a dead link: close and reopen the port."""
    enabled: bool = True
    """false: the agent does not open this sensor (its channels stay empty)."""


class VectorNav(SerialPort):
    """VN-200 INS (binary output, or ASCII $VNYMR/$VNINS)."""

    port: str = "/dev/ttyS1"
    """Device path of the VN-200's serial port."""
    baud: int = Field(921600, ge=1200, le=4_000_000)
    """Baud rate (the VN-200 is set to it: register 5)."""
    protocol: Literal["binary", "ascii"] = "binary"
    """Binary output packets (the thesis's choice) or ASCII sentences."""
    fields: tuple[str, ...] = (
        "common.time_startup",
        "common.time_gps",
        "common.quaternion",
        "common.angular_rate",
        "common.position",
        "common.vel_ned",
        "common.accel",
        "common.ins_status",
    )
    """Binary fields ("group.field"); quaternion or ypr, angular_rate and time_startup are
    needed for attitude, rates and time alignment."""
    configure: bool = False
    """Write binary output register 75 with these fields and rate at every connect."""
    gps_leap_seconds: int = Field(18, ge=0, le=60)
    """GPS − UTC in seconds (18 since 2017-01-01), for converting GPS time to UTC."""

    @model_validator(mode="after")
    def _known_fields(self) -> VectorNav:
        unknown = [f for f in self.fields if f not in field_names()]
        if unknown:
            raise ValueError(f"unknown VN-200 binary fields {unknown}; known: {field_names()}")
        return self


class AirDataPort(SerialPort):
    """Aeroprobe µADC (ASCII lines)."""

    port: str = "/dev/ttyS2"
    """Device path of the µADC's serial port."""
    probe_limit_deg: float = Field(20.0, gt=0.0, le=90.0)
    """Vane/probe range: α or β within 0.05° of it is flagged as clipped."""
    vanes: bool = True
    """The probe measures α and β. false: an airspeed-only probe, whose α and β fields carry
    nothing: they are recorded as missing, and the identification synthesises α and β from
    the INS and an estimated wind (`[identification] air_angles`, docs/identification.md)."""


class Calibration(Section):
    """Potentiometer counts → surface degrees: a table (linear between points) or a
    polynomial deg = Σ c_k counts^k."""

    table: tuple[tuple[float, float], ...] | None = None
    """(counts, degrees) points, counts strictly increasing."""
    poly: tuple[float, ...] | None = None
    """Coefficients c_0, c_1, … of the polynomial in counts."""

    @model_validator(mode="after")
    def _one(self) -> Calibration:
        if (self.table is None) == (self.poly is None):
            raise ValueError("give exactly one of table or poly")
        if self.table is not None:
            counts = [c for c, _ in self.table]
            if len(counts) < 2 or any(b <= a for a, b in itertools.pairwise(counts)):
                raise ValueError("table needs ≥ 2 points with strictly increasing counts")
        return self


def _default_calibration() -> dict[str, Calibration]:
    # 10-bit ADC, 512 counts at neutral, 0.25 °/count: a placeholder until the box is measured.
    return {name: Calibration(poly=(-128.0, 0.25)) for name in CHANNELS}


class SurfacePort(SerialPort):
    """The surface box (seven potentiometers and RPM on an Arduino UNO)."""

    port: str = "/dev/ttyACM0"
    """Device path of the surface box (its Arduino's USB serial port)."""
    calibration: dict[str, Calibration] = Field(default_factory=_default_calibration)
    """Per potentiometer (aileron_left, aileron_right, elevator_left, elevator_right, rudder,
    flap_left, flap_right): counts → degrees, positive by the right-hand rule."""

    @model_validator(mode="after")
    def _all_channels(self) -> SurfacePort:
        missing = sorted(set(CHANNELS) - set(self.calibration))
        unknown = sorted(set(self.calibration) - set(CHANNELS))
        if missing or unknown:
            raise ValueError(
                f"calibration must cover {list(CHANNELS)}; missing {missing}, unknown {unknown}"
            )
        return self


class Sensors(Section):
    """The onboard sensors' ports and options; a sensor set to enabled = false is not opened."""

    vn200: VectorNav = VectorNav()
    """The INS."""
    airdata: AirDataPort = AirDataPort()
    """The air data computer."""
    surfaces: SurfacePort = SurfacePort()
    """The surface-position box."""
    backoff_initial_s: float = Field(0.1, gt=0.0, le=10.0)
    """First wait before reopening a port that failed or vanished."""
    backoff_max_s: float = Field(2.0, gt=0.0, le=60.0)
    """Longest wait between attempts (the wait doubles up to this)."""


class Autopilot(Section):
    """The autopilot link (ArduPlane through MAVSDK)."""

    url: str = "serial:///dev/ttyS3:921600"
    """MAVSDK connection URL: serial:///dev/…:baud, udpin://0.0.0.0:14550 (listen) or
    udpout://host:port (the simulated aircraft)."""
    system_id: int = Field(255, ge=1, le=255)
    """Our MAVLink system id: ArduPilot accepts RC overrides only from SYSID_MYGCS (255)."""
    component_id: int = Field(190, ge=1, le=255)
    """Our MAVLink component id (190: MAV_COMP_ID_MISSIONPLANNER, a GCS)."""
    target_system: int = Field(1, ge=1, le=255)
    """The autopilot's system id (SYSID_THISMAV)."""
    connect_timeout_s: float = Field(10.0, gt=0.0, le=300.0)
    """How long one attempt to find the autopilot waits before it is retried."""
    link_timeout_s: float = Field(0.5, gt=0.0, le=10.0)
    """No message from the autopilot for this long: link lost (a run aborts)."""
    attitude_hz: float = Field(50.0, gt=0.0, le=200.0)
    """ATTITUDE rate (bank, pitch, body rates)."""
    vfr_hud_hz: float = Field(20.0, gt=0.0, le=200.0)
    """VFR_HUD rate (airspeed, altitude, throttle)."""
    aoa_hz: float = Field(20.0, gt=0.0, le=200.0)
    """AOA_SSA rate (angle of attack for the envelope)."""
    rc_channels_hz: float = Field(20.0, gt=0.0, le=200.0)
    """RC_CHANNELS rate (the pilot's excitation switch)."""
    servo_output_hz: float = Field(50.0, gt=0.0, le=200.0)
    """SERVO_OUTPUT_RAW rate (trim capture, commanded surfaces in the log)."""
    nav_controller_hz: float = Field(10.0, gt=0.0, le=200.0)
    """NAV_CONTROLLER_OUTPUT rate (the roll and pitch the autopilot demands: the tracking the
    applied gains are judged by)."""
