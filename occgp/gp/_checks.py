"""Parameter checks shared by the modules of occgp.gp (beyond occgp._validation's)."""

from __future__ import annotations

from .._docfill import fill_doc
from .._validation import check_int, check_real

__all__ = ["check_at_least", "check_angle"]

#: The Parameters every check starts with (see :func:`occgp._docs.fill_doc`).
_VALUE_NAME = """\
Parameters
----------
value : object
    The value to check.
name : str
    The argument's name, for the messages."""


@fill_doc(value_name=_VALUE_NAME)
def check_at_least(value: object, name: str, low: int, high: int | None = None) -> int:
    """Return `value` as an int after checking it is an int (not a bool) in [low, high].

    {value_name}
    low : int
        Smallest accepted value.
    high : int, default=None
        Largest accepted value; None: no upper bound.

    Returns
    -------
    value : int

    Raises
    ------
    TypeError
        If `value` is not an int (a bool is not): ``"<name> must be an int, got float"``.
    ValueError
        If it lies outside the bounds: ``"<name> must be an int >= <low>, got <value>"``
        (or ``"... an int in [<low>, <high>] ..."``).
    """
    v = check_int(value, name)
    if v < low or (high is not None and v > high):
        want = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"{name} must be an int {want}, got {v}")
    return v


@fill_doc(value_name=_VALUE_NAME)
def check_angle(value: object, name: str) -> float:
    """Return `value` as a float after checking it is an angle in [0, 90] degrees.

    {value_name}

    Returns
    -------
    angle : float

    Raises
    ------
    TypeError, ValueError
        As :func:`occgp._validation.check_real`.
    """
    return check_real(value, name, low=0.0, high=90.0, low_open=False, high_open=False)
