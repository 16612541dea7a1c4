"""The expression language of equations models: what it accepts, what it refuses and where.

The accepted expressions are checked by value against Python's own arithmetic (math) evaluated on
the same numbers; the refused ones must name the key and the column of the first character that
leaves the language, and say what was expected there.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from nlsid.errors import InputError
from nlsid.models.expressions import comparisons, parse, source

KEY = "model.derivatives.x1"


def _value(text: str, names: dict) -> float:
    """The generated source of ``text`` evaluated on ``names`` (each name a plain Python float)."""
    expression = parse(text, KEY)
    code = source(expression, {name: f"v[{name!r}]" for name in expression.names})
    return eval(code, {"math": math, "np": np, "v": names})  # noqa: S307 (the test's own text, checked)


@pytest.mark.parametrize("text, expected", [
    ("-k1*sqrt(x1) + k4*u", -0.08 * math.sqrt(6.0) + 0.12 * 2.5),
    ("x1 ** 2 / (1 + x2)", 36.0 / 6.0),
    ("-x1 ** 2", -36.0),                       # ** binds tighter than the sign, as in Python
    ("2 ** -1", 0.5),
    ("abs(-x2) + sign(-3) + sign(0)", 5.0 - 1.0 + 0.0),
    ("exp(log(x1)) + tanh(0.5)", 6.0 + math.tanh(0.5)),
    ("min(x1, x2, 7) + max(x1, x2)", 5.0 + 6.0),
    ("clip(x1, 0, 5.5) + clip(-1, 0, 5.5)", 5.5 + 0.0),
    ("(x1 > x2) + (x1 <= x2) * 10 + (x1 == 6) * 100 + (x1 != 6) * 1000", 1.0 + 100.0),
    ("where(x1 >= 20, 1.0, 2.0)", 2.0),
    ("where(x2 - 5, 1.0, 2.0)", 2.0),           # a condition of 0 is false
    ("where(x2 > 0, sqrt(x2), sqrt(-1 - x2))", math.sqrt(5.0)),  # the branch not taken is not evaluated
    ("1e-3 * x1", 6e-3),
])
def test_values_as_python_computes_them(text, expected):
    assert _value(text, {"x1": 6.0, "x2": 5.0, "k1": 0.08, "k4": 0.12, "u": 2.5}) == pytest.approx(expected, rel=1e-15)


def test_names_and_their_first_columns():
    expression = parse("k2*sqrt(x1) - k3*sqrt(x2) + k2", KEY)
    assert expression.names == {"k2": 1, "x1": 9, "k3": 15, "x2": 23}


def test_comparisons_in_the_order_of_the_text():
    expression = parse("where(x1 >= x1max, 1, 0) + where(x2 < 3, 1, 0)", KEY)
    found = comparisons(expression)
    assert [node.col_offset for node in found] == [7, 34]  # 1-based columns of "x1" and "x2" in the text


@pytest.mark.parametrize("text, column, fragment", [
    ("x1 +* 2", 5, "expected a number, a name, a function call or '(' before '*'"),
    ("__import__('os')", 1, "unknown function '__import__'"),
    ("foo(x1)", 1, "unknown function 'foo'; expected one of sqrt, abs, sign, exp, log, tanh, min, max, clip, where"),
    ("x1.real", 3, "attribute access ('.') is not part of the language"),
    ("x1[0]", 3, "'[' is not part of the language"),
    ("(x1 + 2", 8, "expected ')' to close the '(' at column 1"),
    ("x1 + ", 5, "the text ends where a number, a name, a function call or '(' was expected"),
    ("x1 2", 4, "expected an operator"),
    ("sqrt(x1, x2)", 1, "sqrt() takes 1 argument, got 2"),
    ("clip(x1, 0)", 1, "clip() takes 3 arguments, got 2"),
    ("min(x1)", 1, "min() takes at least 2 arguments, got 1"),
    ("sqrt", 1, "'sqrt' is a function; call it as sqrt(...)"),
    ("lambda: 0", 1, "'lambda' is not part of the language"),
    ("x1 if x2 else 0", 4, "'if' is not part of the language"),
    ("x1 and x2", 4, "'and' is not part of the language"),
    ("x1 % 2", 4, "'%' is not part of the language"),
    ("0 < x1 < 1", 1, "a chained comparison"),
    ("'x1'", 1, "a string is not part of the language"),
    ("2j", 1, "a complex number '2j'; expected a real number"),
    ("x1 # note", 4, "a comment ('#') is not part of the language"),
    ("x1 = 2", 4, "'=' is not part of the language"),
    ("x1, x2", 3, "',' outside a function's arguments"),
    ("min(x1, x2)(3)", 12, "expected an operator"),
])
def test_refused_with_key_and_column(text, column, fragment):
    with pytest.raises(InputError) as info:
        parse(text, KEY)
    assert info.value.where == KEY
    assert info.value.what.startswith(f"column {column}: "), info.value.what
    assert fragment in info.value.what
    assert "\n" not in str(info.value)


def test_empty_and_non_text():
    with pytest.raises(InputError, match="got an empty text"):
        parse("  ", KEY)
    with pytest.raises(InputError, match="expected an expression"):
        parse(True, KEY)
    assert parse(2.5, KEY).names == {}


def test_no_call_ever_reaches_python():
    """The generated source holds only the whitelisted calls, whatever names the text uses."""
    expression = parse("where(u > 0, exp(-x1) * min(x1, k) + abs(sign(u)), clip(log(k), 0, 1))", KEY)
    code = source(expression, {name: "v" for name in expression.names})
    for called in ("math.exp(", "min(", "abs(", "np.sign(", "max(", "math.log("):
        assert called in code
    assert "eval" not in code and "import" not in code and "__" not in code


@pytest.mark.parametrize("text", ["x1 + " * 5000 + "x1", "-" * 5000 + "x1", "x1 * " * 300 + "x1"])
def test_too_deep_a_nesting_is_refused_not_crashed(text):
    with pytest.raises(InputError, match="the expression nests too deeply"):
        parse(text, KEY)


def test_a_long_flat_sum_is_taken():
    assert parse("x1 + " * 150 + "x1", KEY).names == {"x1": 1}
