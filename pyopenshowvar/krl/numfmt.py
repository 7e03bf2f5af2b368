"""REAL number text: the KRC4 print rule and the shortest round-trip literal for writes.

A KRL REAL is an IEEE float32. A KRC4 prints it (a rule derived from, and checked against, 59
REALs captured from KRC4s in public KUKAVARPROXY clients' logs and comments) as ``0.0`` for zero, else C ``%#.6g`` when that text converts back to
the same float32, else ``%#.9g`` (always enough for float32), with the exponent letter
upper-cased: ``90.0000``, ``1339.90503``, ``4.48259061E-06``.

For writes we want the opposite trade-off: the shortest text that reproduces the Python float
(``repr``), which KRL reads with its own float32 rounding. Python's ``%`` formatting is the C
one and ignores the locale, which is exactly what a controller needs.
"""

from __future__ import annotations

import math
import struct

from ..errors import KrlValueError

__all__ = ["FLOAT32_MAX", "float32", "format_real_krc4", "format_real_shortest"]

FLOAT32_MAX = 3.4028234663852886e38

_F32 = struct.Struct("<f")


def float32(x: float) -> float:
    """``x`` rounded to the nearest float32 (as a Python float).

    Raises :class:`KrlValueError` for NaN, infinities and values beyond the float32 range,
    none of which a KRL REAL can hold.
    """
    try:
        return float(_F32.unpack(_F32.pack(x))[0])
    except (OverflowError, struct.error):
        raise KrlValueError(f"{x!r} is out of the KRL REAL (float32) range") from None


def _check_finite(x: float) -> None:
    if not math.isfinite(x):
        raise KrlValueError(f"{x!r} is not a KRL REAL (NaN and infinity are not allowed)")


_pack, _unpack = _F32.pack, _F32.unpack


def format_real_krc4(x: float) -> str:
    """Print ``x`` exactly as a KRC4 prints a REAL holding ``float32(x)``."""
    # The hot path of every read of the simulated robot (a dozen REALs per E6POS, per cycle):
    # the float32 round trips are inlined, and zero (every E1..E6) returns at once.
    if x == 0.0:
        # also -0.0: the controller prints no sign for zero
        return "0.0"
    _check_finite(x)
    try:
        f = _unpack(_pack(x))[0]
    except OverflowError:
        raise KrlValueError(f"{x!r} is out of the KRL REAL (float32) range") from None
    if f == 0.0:  # below float32's smallest subnormal
        return "0.0"
    # printf-style on purpose: this is literally the C conversion the controller uses
    text = "%#.6g" % f  # noqa: UP031
    if _unpack(_pack(float(text)))[0] != f:
        text = "%#.9g" % f  # noqa: UP031
    # only the exponent letter differs from C; "e" appears in nothing else %g prints
    return text.replace("e", "E") if "e" in text else text


def format_real_shortest(x: float) -> str:
    """The shortest literal that parses back to ``x`` exactly, always with ``.`` or ``E``.

    ``1.0``, ``-90.0``, ``1.5E-05``, ``1.0E+16``: the mantissa always has a decimal point so
    that no reader can take the text for an INT.
    """
    _check_finite(x)
    text = repr(float(x))
    mantissa, sep, exponent = text.partition("e")
    if not sep:
        return text  # repr of a finite float without exponent always contains "."
    if "." not in mantissa:
        mantissa += ".0"
    return f"{mantissa}E{exponent}"
