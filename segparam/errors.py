"""The one exception hierarchy of segparam.

Every error that a user can cause (a bad file, a mesh the solver cannot take, a bad option) is a
`SegparamError`; the CLI turns it into one line on stderr and exit code 2.

The ``check_*`` helpers at the end are the option checks shared by the stage configs and the
solver: each returns the value as a plain Python ``int`` / ``float`` / ``str`` / ``bool`` or raises
a :class:`ConfigError` whose message starts with the option's name (``"iterations is 0; it must
be an integer from 1 to 1000"``; :func:`segparam.pipeline.config_from_dict` puts the file and the
``[table]`` in front).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any


class SegparamError(Exception):
    """Base class of every error segparam raises on purpose."""


class InvalidMeshError(SegparamError, ValueError):
    """The mesh is not what the called function needs (shape, indices, topology, size)."""


class MeshFileError(SegparamError, OSError):
    """A mesh file cannot be read (missing, unreadable, unsupported format, not a mesh)."""


class ConfigError(SegparamError, ValueError):
    """A configuration value or file is invalid (unknown key, wrong type, out-of-range value).

    Also a ``ValueError``, so code that caught the ``ValueError`` of a bad option still does.
    """


class SolverError(SegparamError, RuntimeError):
    """A numerical stage failed in a way the input did not predict (e.g. no convergence)."""


# ---------------------------------------------------------------------------------------------
# Option checks (types first: bool is an int subclass but never a number here)
# ---------------------------------------------------------------------------------------------


def _show(value: Any) -> str:
    """``repr`` of a value, numpy scalars shown as the Python value they hold."""
    item = getattr(value, "item", None)
    if callable(item) and type(value).__module__ == "numpy" and getattr(value, "ndim", 1) == 0:
        value = item()
    return repr(value)


def _is_bool(value: Any) -> bool:
    return isinstance(value, bool) or type(value).__name__ == "bool_"  # numpy.bool_ too


def _fail(name: str, value: Any, expected: str, optional: bool) -> ConfigError:
    tail = ", or None" if optional else ""
    return ConfigError(f"{name} is {_show(value)}; it must be {expected}{tail}")


def _range_text(low, high, *, low_open: bool = False, integer: bool = False) -> str:
    kind = "an integer" if integer else "a finite number"
    if low is not None and high is not None:
        if low_open:
            return f"{kind} in ({low}, {high}]"
        return f"{kind} from {low} to {high}"
    if low is not None:
        return f"{kind} {'>' if low_open else '>='} {low}"
    if high is not None:
        return f"{kind} <= {high}"
    return kind


def check_int(
    name: str,
    value: Any,
    *,
    low: int | None = None,
    high: int | None = None,
    optional: bool = False,
) -> int | None:
    """``value`` as an ``int`` in ``[low, high]`` (numpy integers accepted; bool, float, str
    refused), ``None`` if ``optional`` and ``value is None``; else a :class:`ConfigError`."""
    if value is None and optional:
        return None
    expected = _range_text(low, high, integer=True)
    if _is_bool(value) or not isinstance(value, numbers.Integral):
        raise _fail(name, value, expected, optional)
    value = int(value)
    if (low is not None and value < low) or (high is not None and value > high):
        raise _fail(name, value, expected, optional)
    return value


def check_number(
    name: str,
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    optional: bool = False,
) -> float | None:
    """``value`` as a finite ``float`` in ``[low, high]`` (``(low, high]`` with ``low_open``);
    integers and numpy numbers accepted, bool and str refused; ``None`` if ``optional`` and
    ``value is None``; else a :class:`ConfigError`."""
    if value is None and optional:
        return None
    expected = _range_text(low, high, low_open=low_open)
    if _is_bool(value) or not isinstance(value, numbers.Real):
        raise _fail(name, value, expected, optional)
    number = float(value)
    if (
        not math.isfinite(number)
        or (low is not None and (number <= low if low_open else number < low))
        or (high is not None and number > high)
    ):
        raise _fail(name, value, expected, optional)
    return number


def check_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    """``value`` if it is one of the strings ``choices``, else a :class:`ConfigError`."""
    if not isinstance(value, str) or value not in choices:
        raise _fail(name, value, "one of " + ", ".join(repr(c) for c in choices), False)
    return str(value)


def check_bool(name: str, value: Any) -> bool:
    """``value`` if it is a bool (``true`` / ``false`` in TOML), else a :class:`ConfigError`."""
    if not _is_bool(value):
        raise _fail(name, value, "true or false", False)
    return bool(value)
