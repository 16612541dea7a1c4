"""The expression language of an ``equations`` model (``docs/configs.md``, "Models written as equations").

An expression is one line of arithmetic over named numbers:

* numbers (``2``, ``0.5``, ``1e-3``) and names (a state, a parameter, ``u``, ``r``, a channel);
* the operators ``+ - * / **``, unary ``-`` and ``+``, parentheses;
* the comparisons ``< <= > >= == !=``, each worth 1.0 when it holds and 0.0 when not;
* the functions ``sqrt abs sign exp log tanh`` (one argument), ``min max`` (two or more),
  ``clip(x, lower, upper)`` = min(max(x, lower), upper) and ``where(condition, a, b)``: ``a``
  where the condition is nonzero, else ``b``; only the branch taken is evaluated, so
  ``where(x > 0, sqrt(x), 0.0)`` never takes the root of a negative number.

Arithmetic is IEEE double precision without exceptions: a division by zero gives an infinity,
``sqrt`` and ``log`` of a negative number NaN, ``log(0)`` minus infinity; the simulation that
meets such a value stops with an error naming the expression (:mod:`nlsid.models.equations`).

The text is read by Python's own parser (:func:`ast.parse`) and every node of the tree is checked
against the list above: nothing outside it (attribute access, subscripts, strings, keywords,
other functions) is ever evaluated, and the text is never passed to ``eval``. Before that, a scan
of the tokens (:func:`_token_problem`) finds the first place where the text is not an expression
of this language and says what was expected there, with its column (1 = the first character; a
text over several lines is read as one line, its line breaks as spaces).

A checked expression is turned into Python source (:func:`source`) over renamed variables, which
:mod:`nlsid.models.equations` compiles with numba.

Examples
--------
>>> e = parse("-k1*sqrt(x1) + k4*u", "model.derivatives.x1")
>>> sorted(e.names)
['k1', 'k4', 'u', 'x1']
>>> source(e, {"k1": "p[0]", "k4": "p[1]", "u": "w[0]", "x1": "x[0]"})
'((-(p[0]) * math.sqrt(x[0])) + (p[1] * w[0]))'
>>> parse("x1 +* 2", "model.output")
Traceback (most recent call last):
...
nlsid.errors.InputError: model.output: column 5: expected a number, a name, a function call or '(' before '*'
"""

from __future__ import annotations

import ast
import io
import keyword
import tokenize
from dataclasses import dataclass

from nlsid.errors import InputError, one_line

#: function -> (least, most) arguments (None: no upper limit)
FUNCTIONS = {"sqrt": (1, 1), "abs": (1, 1), "sign": (1, 1), "exp": (1, 1), "log": (1, 1), "tanh": (1, 1),
             "min": (2, None), "max": (2, None), "clip": (3, 3), "where": (3, 3)}
OPERATORS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
COMPARISONS = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!="}
_BINARY_TOKENS = {"*", "/", "**", "<", "<=", ">", ">=", "==", "!="}
_OPERAND = "a number, a name, a function call or '('"
_OPERATOR = "an operator (+ - * / ** < <= > >= == !=), ',' or ')'"
_LANGUAGE = "numbers, names, + - * / **, comparisons and the functions " + ", ".join(FUNCTIONS)


@dataclass(frozen=True)
class Expression:
    """A checked expression: its text, the key it was read from, its tree, and the names it reads
    (name -> the column of its first use)."""

    text: str
    where: str
    tree: ast.Expression
    names: dict


def _error(where: str, column: int, what: str) -> InputError:
    return InputError(where, f"column {column}: {what}")


def _tokens(text: str) -> tuple[list, tuple | None]:
    """The tokens of ``text`` (a single line) but the layout ones, and the tokenizer's own error
    (column, message) where it stopped (an unclosed bracket, a stray character)."""
    out = []
    try:
        for token in tokenize.generate_tokens(io.StringIO(text).readline):
            if token.type in (tokenize.NEWLINE, tokenize.NL, tokenize.ENDMARKER, tokenize.INDENT,
                              tokenize.DEDENT) or not token.string.strip():
                continue
            out.append(token)
    except tokenize.TokenError:
        return out, None  # EOF inside brackets: the scan reports the bracket left open
    except (IndentationError, SyntaxError) as exc:  # noqa: B014 (IndentationError is a SyntaxError; named for clarity)
        return out, (max(exc.offset or 1, 1), exc.msg)
    return out, None


def _token_problem(text: str, where: str) -> InputError | None:
    """The first place where ``text`` is not an expression of the language (module docstring), as
    one error with its column and what was expected there; None when the tokens are in order."""
    tokens, stopped = _tokens(text)
    want_operand = True
    brackets: list[tuple[int, bool]] = []  # (column, is a call's argument list)
    previous = None
    for i, token in enumerate(tokens):
        column, value = token.start[1] + 1, token.string
        following = tokens[i + 1].string if i + 1 < len(tokens) else ""
        if token.type == tokenize.NAME:
            if keyword.iskeyword(value):
                return _error(where, column, f"{value!r} is not part of the language; expected {_LANGUAGE}")
            if not want_operand:
                return _error(where, column, f"expected {_OPERATOR} before {value!r}")
            if following == "(" and value not in FUNCTIONS:
                return _error(where, column, f"unknown function {value!r}; expected one of {', '.join(FUNCTIONS)}")
            want_operand = following == "("  # a function's name wants its '('
        elif token.type == tokenize.NUMBER:
            if value[-1] in "jJ":
                return _error(where, column, f"a complex number {value!r}; expected a real number")
            if not want_operand:
                return _error(where, column, f"expected {_OPERATOR} before {value!r}")
            want_operand = False
        elif token.type == tokenize.COMMENT:
            return _error(where, column, f"a comment ('#') is not part of the language; expected {_LANGUAGE}")
        elif token.type == tokenize.STRING:
            return _error(where, column, f"a string is not part of the language; expected {_OPERAND}")
        elif token.type == tokenize.OP and value == "(":
            call = previous is not None and previous.type == tokenize.NAME and previous.string in FUNCTIONS
            if not want_operand:
                return _error(where, column, f"expected {_OPERATOR} before '('")
            brackets.append((column, call))
            want_operand = True
        elif token.type == tokenize.OP and value == ")":
            if not brackets:
                return _error(where, column, "')' closes no '('")
            opened, call = brackets.pop()
            if want_operand and not (call and previous is not None and previous.string == "("):
                return _error(where, column, f"expected {_OPERAND} before ')'")
            want_operand = False
        elif token.type == tokenize.OP and value == ",":
            if not brackets or not brackets[-1][1]:
                return _error(where, column, "',' outside a function's arguments; expected an operator "
                                             "(+ - * / ** < <= > >= == !=)")
            if want_operand:
                return _error(where, column, f"expected {_OPERAND} before ','")
            want_operand = True
        elif token.type == tokenize.OP and value in ("+", "-"):
            want_operand = True  # binary after an operand, unary (sign) before one
        elif token.type == tokenize.OP and value in _BINARY_TOKENS:
            if want_operand:
                return _error(where, column, f"expected {_OPERAND} before {value!r}")
            want_operand = True
        elif token.type == tokenize.OP and value == ".":
            return _error(where, column, "attribute access ('.') is not part of the language; expected "
                          + _OPERATOR)
        else:
            return _error(where, column, f"{value!r} is not part of the language; expected {_LANGUAGE}")
        previous = token
    if stopped is not None:
        return _error(where, stopped[0], f"{stopped[1]}; expected {_LANGUAGE}")
    end = len(text.rstrip()) + 1
    if not tokens:
        return InputError(where, f"expected an expression of {_LANGUAGE}, got an empty text")
    if brackets:
        return _error(where, end, f"expected ')' to close the '(' at column {brackets[-1][0]}")
    if want_operand:
        return _error(where, end, f"the text ends where {_OPERAND} was expected")
    return None


def _check(node: ast.AST, where: str, names: dict) -> None:
    """Raise an error naming the node's column unless ``node`` and everything below it is in the
    language; collect the names read into ``names``."""
    column = max(getattr(node, "col_offset", 1), 1)  # 1-based in the text: the tree is of "(" + text + ")"
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise _error(where, column, f"{node.value!r} is not a number; expected {_OPERAND}")
    elif isinstance(node, ast.Name):
        if node.id in FUNCTIONS:
            raise _error(where, column, f"{node.id!r} is a function; call it as {node.id}(...)")
        names.setdefault(node.id, column)
    elif isinstance(node, ast.BinOp) and type(node.op) in OPERATORS:
        _check(node.left, where, names)
        _check(node.right, where, names)
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        _check(node.operand, where, names)
    elif isinstance(node, ast.Compare):
        if len(node.ops) != 1:
            raise _error(where, column, "a chained comparison; compare two values at a time "
                                        "(where(a < b, where(b < c, ...), ...))")
        if type(node.ops[0]) not in COMPARISONS:
            raise _error(where, column, f"expected a comparison of {' '.join(COMPARISONS.values())}")
        _check(node.left, where, names)
        _check(node.comparators[0], where, names)
    elif isinstance(node, ast.Call):
        name = node.func.id if isinstance(node.func, ast.Name) else None
        if name not in FUNCTIONS:
            raise _error(where, column, f"expected a call of one of {', '.join(FUNCTIONS)}")
        if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
            raise _error(where, column, f"{name}() takes its arguments by position only")
        least, most = FUNCTIONS[name]
        count = len(node.args)
        if count < least or (most is not None and count > most):
            wanted = f"{least}" if least == most else f"at least {least}"
            raise _error(where, column, f"{name}() takes {wanted} argument{'s' if least > 1 else ''}, got {count}")
        for argument in node.args:
            _check(argument, where, names)
    else:
        raise _error(where, column, f"{type(node).__name__} is not part of the language; expected {_LANGUAGE}")


def parse(text, where: str) -> Expression:
    """The checked expression of ``text`` read from the config key ``where``.

    Raises
    ------
    nlsid.errors.InputError
        ``where: column C: what was expected`` for the first place the text leaves the language;
        an expression nested deeper than Python's parser and compiler take (a few hundred
        operations in one chain) is refused as such.
    """
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise InputError(where, f"expected an expression (a text or a number), got {type(text).__name__}")
    line = " ".join(str(text).splitlines()).rstrip()
    problem = _token_problem(line, where)
    if problem is not None:
        raise InputError(problem.where, one_line(problem.what))
    try:
        tree = ast.parse(f"({line})", mode="eval")  # in brackets: leading blanks are no indent
        names: dict = {}
        _check(tree.body, where, names)
        code = source(Expression(str(text), where, tree, names), {name: "v" for name in names})
    except SyntaxError as exc:  # what the token scan let through: Python's own words and place
        raise _error(where, max((exc.offset or 2) - 1, 1), f"{exc.msg}; expected {_LANGUAGE}") from None
    except RecursionError:
        code = None
    if code is not None:
        try:  # the source written from it brackets every operation: it must compile as well
            compile(code, "<expression>", "eval")
        except (SyntaxError, RecursionError, MemoryError):
            code = None
    if code is None:
        raise InputError(where, f"the expression nests too deeply ({len(line)} characters); split it over "
                                "more states or parameters")
    return Expression(str(text), where, tree, names)


def _emit(node: ast.AST, variables: dict, modes: dict) -> str:
    if isinstance(node, ast.Constant):
        return repr(float(node.value))
    if isinstance(node, ast.Name):
        return variables[node.id]
    if isinstance(node, ast.BinOp):
        left, right = _emit(node.left, variables, modes), _emit(node.right, variables, modes)
        return f"({left} {OPERATORS[type(node.op)]} {right})"
    if isinstance(node, ast.UnaryOp):
        sign = "-" if isinstance(node.op, ast.USub) else "+"
        return f"{sign}({_emit(node.operand, variables, modes)})"
    if isinstance(node, ast.Compare):
        if id(node) in modes:
            return modes[id(node)]
        op = COMPARISONS[type(node.ops[0])]
        left, right = _emit(node.left, variables, modes), _emit(node.comparators[0], variables, modes)
        return f"(1.0 if {left} {op} {right} else 0.0)"
    name = node.func.id
    if id(node) in modes:
        return modes[id(node)]
    args = [_emit(a, variables, modes) for a in node.args]
    if name == "where":
        return f"({args[1]} if {args[0]} != 0.0 else {args[2]})"
    if name == "clip":
        return f"min(max({args[0]}, {args[1]}), {args[2]})"
    if name in ("min", "max"):
        return f"{name}({', '.join(args)})"
    if name == "abs":
        return f"abs({args[0]})"
    if name == "sign":
        return f"np.sign({args[0]})"
    return f"math.{name}({args[0]})"


def source(expression: Expression, variables: dict, modes: dict | None = None) -> str:
    """Python source of ``expression`` with each name replaced by ``variables[name]`` (an
    expression such as ``x[0]``); it needs ``math`` and ``np`` (numpy) in its namespace. A
    comparison is a conditional giving 1.0 or 0.0, ``where`` a conditional that evaluates only the
    branch taken. ``modes`` (``id`` of a node of :func:`comparisons` -> source) replaces a
    comparison or a sign by a value held elsewhere (its mode, frozen over an integration step)."""
    return _emit(expression.tree.body, variables, modes or {})


def _jumps(node: ast.AST) -> bool:
    return isinstance(node, ast.Compare) or (isinstance(node, ast.Call) and node.func.id == "sign")


def comparisons(expression: Expression) -> list[ast.AST]:
    """The comparisons and ``sign`` calls of ``expression`` in the order of its text: the places
    where its value jumps as the states move (the switches of :mod:`nlsid.models.equations`)."""
    found = [node for node in ast.walk(expression.tree) if _jumps(node)]
    return sorted(found, key=lambda node: node.col_offset)


def comparison_source(node: ast.AST, variables: dict) -> str:
    """Python source of the value now of one node of :func:`comparisons` (a comparison's 1.0 or
    0.0, a sign's -1.0, 0.0 or 1.0), its operands evaluated as :func:`source` does."""
    return _emit(node, variables, {})
