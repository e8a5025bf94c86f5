"""The LinuxCNC (RS-274/NGC) language of one line: words, parameters, expressions and O words.

A line is read once into a small tree (:func:`read_line`) that the interpreter
(:mod:`cam.formats.gcode`) evaluates each time the line runs, so a loop does not
read its lines again.  LinuxCNC's rules, checked against its ``rs274``:

* case and spaces do not matter outside comments (``G 0 1`` is ``G01``);
* a value is a number, ``#`` parameter (``#1``, ``#[1+2]``, ``##1``, ``#<name>``), an
  expression in ``[ ]``, a function (``SIN[..]``, ``ATAN[..]/[..]``, ``EXISTS[#<name>]``)
  or any of these after a unary ``-`` or ``+``;
* binary operators, strongest first: ``**``; ``*``, ``/``, ``MOD``; ``+``, ``-``;
  ``EQ NE GT GE LT LE`` (``EQ`` and ``NE`` within 0.0001, as rs274); ``AND OR XOR``; left to right
  within a level;
* trigonometry in degrees; ``FIX`` rounds down, ``FUP`` up, ``ROUND`` half away from zero;
  ``a MOD b`` is ``fmod`` made non-negative by adding ``|b|``.

Standard library only.
"""
from __future__ import annotations

import math
import re
from typing import Callable

__all__ = ["NgcSyntaxError", "Line", "read_line", "evaluate", "O_KEYWORDS"]


class NgcSyntaxError(Exception):
    """A line cannot be read; the interpreter adds the file, the line and the word."""


O_KEYWORDS = ("endsub", "endwhile", "endif", "endrepeat", "elseif", "else", "sub", "call", "do", "while", "if",
              "break", "continue", "return", "repeat")

NUMBER = r"\d+(?:\.\d*)?|\.\d+"
r"""An unsigned decimal number, as G-code writes it (``12``, ``1.``, ``.5``, ``1.25``); every pattern of the G-code
reader that reads one is made from this.  Each number matches one way only: ``\d+\.?\d*`` could split ``2001``
into ``20`` and ``01``, and a long line of words that did not fit a pattern then backtracked exponentially."""
_NUMBER = re.compile(NUMBER)
PLAIN_NUMBERS = True
"""Read words with plain numbers by :data:`_PLAIN_WORDS` and :data:`_SIGNED`; False: every value by
:meth:`_Reader.value` (the tests compare the two)."""
_SIGNED = re.compile(rf"([-+]?)({NUMBER})")
"""A word's value when it is a plain number (the most common case): read as :meth:`_Reader.value` reads it."""
_PLAIN_WORDS = re.compile(rf"(?:[a-z@^][-+]?(?:{NUMBER}))+")
"""A line of words with plain numbers only (``g1x1.5y-2``): each word ends where the next letter starts."""
_WORD = re.compile(rf"([a-z@^])([-+]?)({NUMBER})")
_NAME_OPS = ("mod", "eq", "ne", "gt", "ge", "lt", "le", "and", "or", "xor")
_PRECEDENCE = {"**": 4, "*": 3, "/": 3, "mod": 3, "+": 2, "-": 2,
               "eq": 1, "ne": 1, "gt": 1, "ge": 1, "lt": 1, "le": 1, "and": 0, "or": 0, "xor": 0}
_FUNCTIONS = ("abs", "acos", "asin", "atan", "cos", "exp", "fix", "fup", "ln", "round", "sin", "sqrt", "tan",
              "exists")
EQUAL_TOLERANCE = 1e-4  # rs274: 1 EQ 1.00005 is true, 1 EQ 1.001 false


class Line:
    """One line read: ``o`` (label, keyword, argument expressions) for an O word, else ``words``
    (letter, value tree, the word as written) and ``assigns`` (parameter, value tree)."""

    __slots__ = ("o", "words", "assigns")

    def __init__(self) -> None:
        self.o: tuple[str, str, list] | None = None
        self.words: list[tuple[str, object, str]] = []
        self.assigns: list[tuple[object, object]] = []


class _Reader:
    def __init__(self, text: str) -> None:
        self.s = text
        self.i = 0

    def peek(self, n: int = 1) -> str:
        return self.s[self.i:self.i + n]

    def fail(self, what: str) -> NgcSyntaxError:
        rest = self.s[self.i:self.i + 20]
        return NgcSyntaxError(f"{what} at '{rest}'" if rest else f"{what} at the end of the line")

    def number(self) -> tuple:
        m = _NUMBER.match(self.s, self.i)
        if not m:
            raise self.fail("expected a number")
        self.i = m.end()
        return ("n", float(m.group(0)))

    def parameter(self) -> tuple:
        """After '#': ``("name", str)`` or ``("num", tree)``."""
        c = self.peek()
        if c == "<":
            j = self.s.find(">", self.i)
            if j < 0:
                raise self.fail("named parameter without '>'")
            name = self.s[self.i + 1:j]
            if not name:
                raise self.fail("empty parameter name")
            self.i = j + 1
            return ("name", name)
        return ("num", self.value())

    def value(self) -> tuple:
        c = self.peek()
        if c == "[":
            self.i += 1
            return self.expression()
        if c == "#":
            self.i += 1
            return ("p", self.parameter())
        if c and c in "-+":
            self.i += 1
            inner = self.value()
            return ("neg", inner) if c == "-" else inner
        if c.isalpha():
            for name in _FUNCTIONS:
                if self.s.startswith(name, self.i):
                    self.i += len(name)
                    if self.peek() != "[":
                        raise self.fail(f"function '{name.upper()}' needs '['")
                    if name == "exists":
                        self.i += 1
                        if self.peek() != "#":
                            raise self.fail("EXISTS needs a parameter")
                        self.i += 1
                        ref = self.parameter()
                        if self.peek() != "]":
                            raise self.fail("EXISTS needs ']'")
                        self.i += 1
                        return ("exists", ref)
                    self.i += 1
                    arg = self.expression()
                    if name == "atan":
                        if self.peek(2) != "/[":
                            raise self.fail("ATAN needs the form ATAN[y]/[x]")
                        self.i += 2
                        return ("atan", arg, self.expression())
                    return ("f", name, arg)
            raise self.fail("unknown function")
        return self.number()

    def operator(self) -> str | None:
        if self.peek(2) == "**":
            self.i += 2
            return "**"
        c = self.peek()
        if c and c in "*/+-":
            self.i += 1
            return c
        for name in _NAME_OPS:
            if self.s.startswith(name, self.i):
                self.i += len(name)
                return name
        return None

    def expression(self) -> tuple:
        """After '[': values and operators up to the matching ']'."""
        values = [self.value()]
        ops: list[str] = []

        def reduce_to(level: int) -> None:
            while ops and _PRECEDENCE[ops[-1]] >= level:
                b, a = values.pop(), values.pop()
                values.append(("b", ops.pop(), a, b))

        while True:
            if self.peek() == "]":
                self.i += 1
                reduce_to(-1)
                return values[0]
            op = self.operator()
            if op is None:
                raise self.fail("expected an operator or ']'")
            reduce_to(_PRECEDENCE[op])
            ops.append(op)
            values.append(self.value())


def read_line(body: str) -> Line:
    """Read one line: lower case, no spaces, no comments.

    Raises:
        NgcSyntaxError: the line cannot be read (the message quotes where).
    """
    line = Line()
    r = _Reader(body)
    if body.startswith("o"):
        r.i = 1
        if r.peek() == "<":
            j = body.find(">")
            if j < 0:
                raise r.fail("O word name without '>'")
            label = body[1:j + 1]
            r.i = j + 1
        else:
            m = _NUMBER.match(body, 1)
            if not m:
                raise r.fail("O word needs a number or a <name>")
            label = str(int(float(m.group(0))))
            r.i = m.end()
            if r.i == len(body):  # a bare program number ('O1000'), as rs274 reads it: nothing to run
                return line
        for kw in O_KEYWORDS:
            if body.startswith(kw, r.i):
                r.i += len(kw)
                break
        else:
            raise r.fail("unknown O word keyword")
        args = []
        while r.peek() == "[":
            r.i += 1
            args.append(r.expression())
        if r.i < len(body):
            raise r.fail("unexpected text after the O word")
        line.o = (label, kw, args)
        return line
    if PLAIN_NUMBERS and _PLAIN_WORDS.fullmatch(body):  # the words the loop below would read, without its steps
        for m in _WORD.finditer(body):
            c, sign, digits = m.groups()
            tree = ("n", float(digits))
            line.words.append((c, ("neg", tree) if sign == "-" else tree, m.group(0)))
        return line
    while r.i < len(body):
        c = r.peek()
        start = r.i
        if c == "#":
            r.i += 1
            ref = r.parameter()
            if r.peek() != "=":
                raise r.fail("a parameter alone needs '='")
            r.i += 1
            line.assigns.append((ref, r.value()))
        elif c.isalpha() or c in "@^":
            r.i += 1
            nxt = r.peek()
            if not nxt or nxt.isalpha() and not any(body.startswith(f, r.i) for f in _FUNCTIONS):
                raise NgcSyntaxError(f"word '{c.upper()}' has no number")
            m = _SIGNED.match(body, r.i) if PLAIN_NUMBERS else None
            if m is not None:  # the tree value() makes of it: a sign is a "neg" node, as '-' before any value
                r.i = m.end()
                tree = ("n", float(m.group(2)))
                if m.group(1) == "-":
                    tree = ("neg", tree)
            else:
                tree = r.value()
            line.words.append((c, tree, body[start:r.i]))
        else:
            raise r.fail("cannot read")
    return line


def _round(v: float) -> float:
    return float(math.floor(v + 0.5)) if v >= 0 else -float(math.floor(-v + 0.5))


_UNARY: dict[str, Callable[[float], float]] = {
    "abs": abs, "acos": lambda v: math.degrees(math.acos(v)), "asin": lambda v: math.degrees(math.asin(v)),
    "cos": lambda v: math.cos(math.radians(v)), "exp": math.exp, "fix": lambda v: float(math.floor(v)),
    "fup": lambda v: float(math.ceil(v)), "ln": math.log, "round": _round,
    "sin": lambda v: math.sin(math.radians(v)), "sqrt": math.sqrt, "tan": lambda v: math.tan(math.radians(v)),
}


def binary(op: str, a: float, b: float) -> float:
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if op == "/":
        if b == 0:
            raise NgcSyntaxError("division by zero")
        return a / b
    if op == "mod":
        if b == 0:
            raise NgcSyntaxError("MOD by zero")
        m = math.fmod(a, b)
        return m + abs(b) if m < 0 else m
    if op == "**":
        if a < 0 and b != int(b):
            raise NgcSyntaxError("negative base to a fractional power")
        if a == 0 and b < 0:
            raise NgcSyntaxError("zero to a negative power")
        return math.pow(a, b)
    if op == "eq":
        return float(abs(a - b) < EQUAL_TOLERANCE)
    if op == "ne":
        return float(abs(a - b) >= EQUAL_TOLERANCE)
    if op == "gt":
        return float(a > b)
    if op == "ge":
        return float(a >= b)
    if op == "lt":
        return float(a < b)
    if op == "le":
        return float(a <= b)
    if op == "and":
        return float(a != 0 and b != 0)
    if op == "or":
        return float(a != 0 or b != 0)
    return float((a != 0) != (b != 0))  # xor


def evaluate(tree: tuple, read: Callable[[tuple], float], exists: Callable[[tuple], bool]) -> float:
    """The value of a tree; ``read(ref)`` gives a parameter's value, ``exists(ref)`` whether it is set.

    Raises:
        NgcSyntaxError: division by zero, a function outside its domain, a result that is not finite.
    """
    kind = tree[0]
    try:
        if kind == "n":
            v = tree[1]
        elif kind == "p":
            ref = tree[1]
            if ref[0] == "num":
                ref = ("num", evaluate(ref[1], read, exists))
            v = read(ref)
        elif kind == "neg":
            v = -evaluate(tree[1], read, exists)
        elif kind == "b":
            v = binary(tree[1], evaluate(tree[2], read, exists), evaluate(tree[3], read, exists))
        elif kind == "f":
            v = _UNARY[tree[1]](evaluate(tree[2], read, exists))
        elif kind == "atan":
            v = math.degrees(math.atan2(evaluate(tree[1], read, exists), evaluate(tree[2], read, exists)))
        else:  # exists
            ref = tree[1]
            if ref[0] == "num":
                ref = ("num", evaluate(ref[1], read, exists))
            v = float(exists(ref))
    except (ValueError, OverflowError):
        name = tree[1].upper() if kind == "f" else {"b": "the operator", "atan": "ATAN"}.get(kind, "a value")
        raise NgcSyntaxError(f"{name} has no finite value here") from None
    if kind != "n" and not math.isfinite(v):  # a number of 400 digits is left to the word's range check
        raise NgcSyntaxError("an expression has no finite value")
    return v
