"""A value rounded to its standard error: the one rule of every table and figure.

The rule is the fit tables' (demfit::round_to_error, fit/src/table.cpp), and
tests/python/test_rounding.py checks that both give the same text on the same numbers: the error
keeps one significant digit, two when its first digit is 1 (0.0014 would otherwise become 0.001,
30 % off); the value is rounded to the same decimal place. Magnitudes >= 1e5, or value and error
both below 1e-3, go to scientific notation (1.23(2)e-5). A non-finite or non-positive error gives
the value to 3 significant digits and no error.

    paren(0.196534, 0.00231554) -> "0.197(2)"      pm(0.196534, 0.00231554) -> "0.197 ± 0.002"
    paren(3.7e-4, 1.1e-4)       -> "3.7(11)e-4"    pm(3.7e-4, 1.1e-4)       -> "(3.7 ± 1.1)e-4"
"""
import math
from decimal import Decimal


def _sig3(v):
    return f"{v:.3g}"


def _fixed(n, decimals):
    """The integer n with its decimal point `decimals` digits from the right."""
    return format(Decimal(int(n)).scaleb(-decimals), "f") if decimals > 0 else str(int(n) * 10 ** (-decimals))


def round_to_error(v, e):
    """(value, error in units of the last digit, error in the value's units, exponent); value "nan"
    for a non-finite value; error "" when there is none."""
    if not math.isfinite(v):
        return "nan", "", "", 0
    if not (math.isfinite(e) and e > 0):
        return _sig3(v), "", "", 0
    exponent = 0
    if abs(v) >= 1e5 or (abs(v) < 1e-3 and e < 1e-3):
        exponent = math.floor(math.log10(max(abs(v), e)))
        v, e = v / 10.0 ** exponent, e / 10.0 ** exponent
    d = math.floor(math.log10(e))
    lead = e / 10.0 ** d
    if lead >= 10:
        d, lead = d + 1, lead / 10
    if lead < 1:
        d, lead = d - 1, lead * 10
    place = d - (2 if lead < 2 else 1) + 1          # power of ten of the last digit kept
    scale = 10.0 ** -place if place < 0 else 1 / 10.0 ** place
    nv, ne = _round_half_away(v * scale), _round_half_away(e * scale)
    if abs(nv) > 1e15:   # an error far below the value's precision: no rounding to speak of
        return f"{v:.15g}", f"{e:.2g}", f"{e:.2g}", exponent
    value = _fixed(nv, -place)
    error = str(ne) if place < 0 else _fixed(ne, -place)
    return value, error, _fixed(ne, -place), exponent


def _round_half_away(x):
    """std::round: halves away from zero (Python's round() goes to even)."""
    return int(math.floor(abs(x) + 0.5)) * (1 if x >= 0 else -1)


def paren(v, e):
    """"0.197(2)", "1.23(2)e-5"; "nan" for a non-finite value; the value alone without an error."""
    value, error, _, exponent = round_to_error(v, e)
    return value + (f"({error})" if error else "") + (f"e{exponent}" if exponent else "")


def pm(v, e):
    """"0.197 ± 0.002", "(1.23 ± 0.02)e-5"; "n/a" for a non-finite value."""
    if not math.isfinite(v):
        return "n/a"
    value, error, error_abs, exponent = round_to_error(v, e)
    if not error:
        return value + (f"e{exponent}" if exponent else "")
    s = f"{value} ± {error_abs}"
    return f"({s})e{exponent}" if exponent else s
