"""Typed errors of the identification core.

Two families, so callers can map them to the right outcome:
- `DataError`: the data cannot be used as given (bad shapes, too short, constant channels).
  The command line reports these as bad input (exit 2).
- `IdentificationFailed`: the data was usable but the numerics could not produce a model
  (no dynamics above the noise floor, a singular regression). Exit 1.
"""


class IdentError(Exception):
    """Base of every error raised by `agent.ident`."""


class DataError(IdentError, ValueError):
    """The input arrays cannot be identified from as given; the message says what to change."""


class InsufficientDataError(DataError):
    """Too few samples for the requested number of Markov parameters or Hankel size."""


class ConstantChannelError(DataError):
    """A channel never moves, so its effect (or response) cannot be identified."""


class IdentificationFailed(IdentError):
    """The numerics could not produce a model from usable data; the message says why."""


class ContinuousConversionError(IdentError):
    """A discrete model has no real continuous-time equivalent (eigenvalue on the negative axis)."""
