"""evstwin._checks: one semantics for every argument check (a wrong type is a TypeError that is
also a ValueError; a bad value a ValueError; the message names the argument and the value)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from evstwin import _checks, analysis, psf
from evstwin._checks import WrongTypeError
from evstwin.optics import Optics


@pytest.mark.parametrize("value", [True, np.True_, "1.5", None, [1.0], 1 + 2j])
def test_a_non_number_is_a_wrong_type(value: object) -> None:
    with pytest.raises(WrongTypeError, match=r"x must be a real number; got x="):
        _checks.finite("x", value)


def test_a_wrong_type_is_caught_as_either_error() -> None:
    for kind in (TypeError, ValueError):
        with pytest.raises(kind):
            _checks.finite("x", "abc")


@pytest.mark.parametrize(("value", "expected"), [(2, 2.0), (np.float32(0.5), 0.5), (np.int64(-3), -3.0),
                                                 (Fraction(1, 4), 0.25)])
def test_real_numbers_of_any_kind_are_floats(value: object, expected: float) -> None:
    out = _checks.finite("x", value)
    assert out == expected and type(out) is float


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 10**400])
def test_nan_infinity_and_overflow_are_bad_values(value: object) -> None:
    with pytest.raises(ValueError, match=r"x must be a finite number; got x=") as info:
        _checks.finite("x", value)
    assert not isinstance(info.value, TypeError)


def test_positive_and_non_negative_bounds() -> None:
    assert _checks.non_negative("x", 0) == 0.0
    with pytest.raises(ValueError, match=r"x must be > 0; got x=0"):
        _checks.positive("x", 0)
    with pytest.raises(ValueError, match=r"x must be >= 0; got x=-1e-300"):
        _checks.non_negative("x", -1e-300)


@pytest.mark.parametrize("value", [2.7, 2.0, True, "3", np.float64(3.0)])
def test_a_non_integer_is_not_an_integer(value: object) -> None:
    with pytest.raises(WrongTypeError, match=r"n must be an integer; got n="):
        _checks.integer("n", value)


def test_integer_ranges_name_their_bounds() -> None:
    assert _checks.integer("n", np.int16(5), 0, 5) == 5
    with pytest.raises(ValueError, match=r"n must be an integer in \[0, 5\]; got n=6"):
        _checks.integer("n", 6, 0, 5)
    with pytest.raises(ValueError, match=r"n must be an integer >= 1; got n=0"):
        _checks.integer("n", 0, 1)
    with pytest.raises(ValueError, match=r"n must be an integer <= 1; got n=2"):
        _checks.integer("n", 2, maximum=1)


@pytest.mark.parametrize(("width", "height", "kind"), [(True, 4, WrongTypeError), (2.7, 4, WrongTypeError),
                                                       (4, 0, ValueError), (4, -2, ValueError)])
def test_sizes_are_positive_integers_everywhere(width: object, height: object, kind: type) -> None:
    """The two size checks that disagreed (analysis took True and 2.7, psf refused them) are one."""
    events = np.zeros(0, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    for call in (lambda: _checks.size(width, height), lambda: analysis.stats(events, width, height),  # type: ignore[arg-type]
                 lambda: psf.render_points(width, height, [], [], [], 1.0)):  # type: ignore[arg-type]
        with pytest.raises(kind, match=r"(width|height) must be a positive integer; got (width|height)="):
            call()


def test_arrays_refuse_booleans_strings_and_non_finite_values() -> None:
    np.testing.assert_array_equal(_checks.array("a", [1, 2.5]), [1.0, 2.5])
    assert _checks.array("a", np.array([], np.float32)).dtype == np.float64
    for bad in ([True, False], ["1", "2"], "3", [1, None], [1 + 1j]):
        with pytest.raises(WrongTypeError, match=r"a must be a real number or array of them"):
            _checks.array("a", bad)
    with pytest.raises(ValueError, match=r"a must be finite; got a containing nan"):
        _checks.array("a", [1.0, math.nan])
    with pytest.raises(ValueError, match=r"a must be > 0; got a containing 0"):
        _checks.array("a", [1.0, 0.0], min_value=0.0, strict=True)


def test_optics_take_the_shared_checks() -> None:
    with pytest.raises(WrongTypeError, match=r"f_number must be a real number; got f_number=True"):
        Optics(f_number=True)  # type: ignore[arg-type]
    with pytest.raises(WrongTypeError, match=r"width_px must be an integer; got width_px=346.0"):
        Optics(width_px=346.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"width_px must be an integer >= 1; got width_px=0"):
        Optics(width_px=0)
