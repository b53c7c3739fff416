"""The one error type that reaches the user as a single line and exit status 2, and the TOML reader
that raises it."""
import tomllib
from pathlib import Path


class InputError(Exception):
    """Bad input (file, parameter, flag): the message names the file, row or column and what is wrong."""


def read_toml(path, text: str | None = None) -> dict:
    """Parse a TOML file (or `text` under that name); a missing or malformed file is an InputError."""
    if text is None:
        try:
            text = Path(path).read_text()
        except OSError as e:
            raise InputError(f"{path}: cannot read ({e.strerror})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: not valid TOML ({e})") from None
