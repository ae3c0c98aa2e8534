"""Argument checks: the one set every module uses, with one semantics.

* A value of the wrong *type* raises :class:`WrongTypeError`, a ``TypeError``: ``True`` or
  ``np.True_`` where a number is asked (a bool is not a number), a string, ``None``, and a
  number that is not an integer (``2.7``, ``2.0``) where an integer, a count or a size is
  asked. ``WrongTypeError`` is also a ``ValueError`` (as numpy's ``AxisError`` is both a
  ``ValueError`` and an ``IndexError``), so code that catches ``ValueError`` for any bad
  argument, as the CLI and the scenario loader do, still catches it.
* A value of the right type that is out of its domain raises ``ValueError``: NaN, an
  infinity, a number too large for a float, a negative count, anything outside its range.

Every message is one line naming the argument and the value given:
``width must be a positive integer; got width=2.7``.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np
import numpy.typing as npt


class WrongTypeError(TypeError, ValueError):
    """An argument of the wrong type (a ``TypeError``, and a ``ValueError`` for callers that
    catch every bad argument as one)."""


def is_real(value: Any) -> bool:
    """A real number (Python or numpy, ints included), not a bool."""
    if type(value) is float or type(value) is int:  # the common case, without the ABC's checks
        return True  # (a bool's type is bool)
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def is_integer(value: Any) -> bool:
    """An integer (Python or numpy), not a bool; ``2.0`` is not one."""
    if type(value) is int:  # the common case, without the ABC's checks (a bool's type is bool)
        return True
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def finite(name: str, value: Any) -> float:
    """``value`` as a float: a real number (WrongTypeError otherwise), finite (ValueError)."""
    if not is_real(value):
        raise WrongTypeError(f"{name} must be a real number; got {name}={value!r}")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number; got {name}={value!r}")
    return v


def positive(name: str, value: Any) -> float:
    """A finite number > 0, as a float."""
    v = finite(name, value)
    if v <= 0.0:
        raise ValueError(f"{name} must be > 0; got {name}={value!r}")
    return v


def non_negative(name: str, value: Any) -> float:
    """A finite number >= 0, as a float."""
    v = finite(name, value)
    if v < 0.0:
        raise ValueError(f"{name} must be >= 0; got {name}={value!r}")
    return v


def in_range(name: str, value: Any, lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False,
             note: str = "") -> float:
    """A finite number in [lo, hi] (an end left out where ``lo_open`` / ``hi_open``), as a float;
    the message writes the interval: ``halo_beta must be in (1, 10] (a finite flux); got
    halo_beta=11``, ``note`` (a unit, a reason) after it."""
    v = finite(name, value)
    if not (lo < v if lo_open else lo <= v) or not (v < hi if hi_open else v <= hi):
        interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        raise ValueError(f"{name} must be in {interval}{' ' + note if note else ''}; got {name}={value!r}")
    return v


def integer(name: str, value: Any, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an int: an integer (WrongTypeError otherwise: not a bool, not 2.0), in
    [minimum, maximum] where given (ValueError)."""
    if not is_integer(value):
        raise WrongTypeError(f"{name} must be an integer; got {name}={value!r}")
    v = int(value)
    if (minimum is not None and v < minimum) or (maximum is not None and v > maximum):
        if maximum is None:
            bound = f">= {minimum}"
        elif minimum is None:
            bound = f"<= {maximum}"
        else:
            bound = f"in [{minimum}, {maximum}]"
        raise ValueError(f"{name} must be an integer {bound}; got {name}={value!r}")
    return v


def size(width: Any, height: Any) -> tuple[int, int]:
    """A sensor or image size: two integers >= 1, named width and height."""
    for name, v in (("width", width), ("height", height)):
        if not is_integer(v) or v < 1:
            error = ValueError if is_integer(v) else WrongTypeError
            raise error(f"{name} must be a positive integer; got {name}={v!r}")
    return int(width), int(height)


def array(name: str, value: npt.ArrayLike, *, min_value: float | None = None, strict: bool = False) -> np.ndarray:
    """``value`` as a float64 array, every element finite and, where given, >= min_value
    (> with ``strict``). Booleans, strings and complex numbers are not real numbers
    (WrongTypeError)."""
    try:
        raw = np.asarray(value)
        if raw.dtype.kind == "O":  # Python objects: numbers (Fractions, huge ints) only, not None
            raw = raw.astype(np.float64) if all(is_real(v) for v in raw.ravel()) else np.asarray(None, dtype=object)
    except (TypeError, ValueError, OverflowError):
        raw = np.asarray(None, dtype=object)
    if raw.dtype.kind not in "iuf":
        raise WrongTypeError(f"{name} must be a real number or array of them; got {name}={value!r}")
    a = np.asarray(raw, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        bad = a[~np.isfinite(a)].ravel()[0]
        raise ValueError(f"{name} must be finite; got {name} containing {bad}")
    if min_value is not None:
        bad_mask = a <= min_value if strict else a < min_value
        if np.any(bad_mask):
            bad = a[bad_mask].ravel()[0]
            op = ">" if strict else ">="
            raise ValueError(f"{name} must be {op} {min_value:g}; got {name} containing {bad:g}")
    return a
