"""Unit strings as FMI unit definitions: `N.m`, `m/(s.N)`, `N2/s5`, `1/(N.m)`, `N/s0.5`.

Grammar: factors joined by `.`, each a symbol with an optional exponent (`m2`, `s0.5`), an optional
`/` and a denominator that is one factor or a parenthesised product. `1` is dimensionless. Symbols
with SI base-unit expansions get a BaseUnit element (integer exponents only, as FMI 2.0 requires);
the others are defined by name alone.
"""

from __future__ import annotations

import math
import re
from collections import Counter

__all__ = ["base_units"]

_BASE = {
    "kg": {"kg": 1},
    "m": {"m": 1},
    "s": {"s": 1},
    "rad": {"rad": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "Hz": {"s": -1},
    "deg": {"rad": 1},
}
_SCALE = {"deg": math.pi / 180.0}
_FACTOR = re.compile(r"^(?P<symbol>[A-Za-z]+)(?P<exponent>\d+(\.\d+)?)?$")


def _product(text: str) -> tuple[Counter[str], float] | None:
    total: Counter[str] = Counter()
    scale = 1.0
    for factor in text.split("."):
        if factor == "1":
            continue
        match = _FACTOR.match(factor)
        if match is None or match["symbol"] not in _BASE:
            return None
        exponent = float(match["exponent"] or 1)
        if exponent != int(exponent):
            return None
        for base, power in _BASE[match["symbol"]].items():
            total[base] += power * int(exponent)
        scale *= _SCALE.get(match["symbol"], 1.0) ** exponent
    return total, scale


def base_units(unit: str) -> tuple[dict[str, int], float] | None:
    """(SI base-unit exponents, factor) of `unit`: value in SI = factor · value in `unit`.
    ({}, 1.0) for dimensionless; None for a unit with no integer expansion we know."""
    numerator, _, denominator = unit.partition("/")
    top = _product(numerator)
    bottom = _product(denominator.strip("()")) if denominator else (Counter(), 1.0)
    if top is None or bottom is None:
        return None
    exponents = top[0]
    exponents.subtract(bottom[0])
    return {k: v for k, v in sorted(exponents.items()) if v != 0}, top[1] / bottom[1]
