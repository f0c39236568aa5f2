"""ground.toml: the console's configuration (radio, aircraft address, key, logs)."""

from __future__ import annotations

from pydantic import Field

from agent.config import Excitation, Link, Section


class GroundConfig(Section):
    """The whole ground configuration file."""

    link: Link = Link(counter_file="ground.counter", seen_file="ground.seen")
    """The ground XBee: port, baud, `peer` = the aircraft's 64-bit address, the shared key
    file, this end's counter and highest-seen files."""
    log_dir: str = "ground-logs"
    """Where the ground log goes (every message received and command sent, JSON lines)."""
    stale_s: float = Field(3.0, gt=0.0, le=60.0)
    """Status older than this is shown as stale."""
    excitation: Excitation = Excitation()
    """A copy of the aircraft's [excitation] section: the preview checks a plan against the
    same surfaces, limits and command rate before it is sent (the aircraft decides)."""
    rssi_s: float = Field(2.0, gt=0.0, le=60.0)
    """How often the ground module's RSSI of the last frame (AT DB) is read."""
    results_kept: int = Field(200, ge=1, le=10_000)
    """Results reloaded from earlier ground logs at start and kept in memory."""
