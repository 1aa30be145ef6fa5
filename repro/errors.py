"""One exception hierarchy for the suite.

Every message names the bad value and, where there is a finite set of valid
choices, lists them (as in mink's exceptions).
"""

from __future__ import annotations

from collections.abc import Iterable


class ReproError(Exception):
    """Base class of every error raised by repro."""


class ConfigError(ReproError, ValueError):
    """A configuration value or CLI override is malformed or out of range."""


class UnknownChoiceError(ConfigError):
    """A name (experiment, solver, model...) is not one of the valid choices."""

    def __init__(self, kind: str, value: object, choices: Iterable[str]) -> None:
        self.kind = kind
        self.value = value
        self.choices = sorted(choices)
        super().__init__(
            f"unknown {kind} {value!r}; valid choices: {', '.join(self.choices)}"
        )


class NonFiniteInputError(ReproError, ValueError):
    """A control or vision input (features, error, Jacobian, gain, limit, pose) holds NaN or
    inf. Raised instead of letting a NaN reach a joint command; a lost feature's NaN should be
    handled before the control law (select the found features, or stop)."""


class SolverError(ReproError):
    """A numerical solver failed in a way the caller must handle."""


class SensorError(ReproError):
    """A sensor produced an unusable reading (NaN, lost feature...)."""
