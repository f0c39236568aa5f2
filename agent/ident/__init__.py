"""The identification core: OKID, ERA, modes and quality indicators, fit — pure numpy/scipy."""

from agent.ident.errors import (
    ConstantChannelError,
    ContinuousConversionError,
    DataError,
    IdentError,
    IdentificationFailed,
    InsufficientDataError,
)
from agent.ident.okid import Experiment
from agent.ident.pipeline import identify
from agent.ident.result import Identification
from agent.ident.settings import Settings

__all__ = [
    "ConstantChannelError",
    "ContinuousConversionError",
    "DataError",
    "Experiment",
    "IdentError",
    "Identification",
    "IdentificationFailed",
    "InsufficientDataError",
    "Settings",
    "identify",
]
