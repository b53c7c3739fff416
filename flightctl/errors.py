"""The one error type that reaches the user as a single line and exit status 2 (`InputError`, and the
`Parser` whose errors are one), and the checks of values typed or written as numbers (`seed`,
`parse_number`, `number`). The checked readers and the atomic writer are flightctl/files.py."""
import argparse
import math
import re


class InputError(Exception):
    """Bad input (file, parameter, flag): the message names the file, row or column and what is wrong."""


class Parser(argparse.ArgumentParser):
    """argparse's parser whose errors (an unknown flag, a value that is not a number) are an InputError:
    one line naming the command (flightctl/cli.py) and exit 2, not argparse's usage block."""

    def error(self, message):
        raise InputError(message)


def seed(text: str) -> int:
    """`--seed`: a whole number from 0 (numpy's generators take no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise InputError(f"--seed {text}: a whole number from 0 is needed") from None
    if not 0 <= value < 2 ** 63:
        raise InputError(f"--seed {text}: a whole number from 0 to 2^63 - 1 is needed")
    return value


# A number as measured data writes it: digits with an optional point and exponent, or nan / inf.
# Python's float() also takes '1_0' (10), ' 5 ' (5) and other digits than 0-9: a cell meant as
# something else is refused instead of read as a number.
NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?(?:nan|inf|infinity)", re.IGNORECASE | re.ASCII)
NUMBER_CHARS = frozenset("0123456789.eE+-nNaAiIfFtTyY")   # every character NUMBER can match


def parse_number(cell: str) -> float | None:
    """The value of a cell written as a number (NUMBER), else None. nan and inf are returned as such."""
    return float(cell) if NUMBER.fullmatch(cell) else None


def number(value) -> float | None:
    """A TOML value as a finite float, or None (a bool, text, a table, inf, nan, an integer beyond
    the float range)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        v = float(value)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None
