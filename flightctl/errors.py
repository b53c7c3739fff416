"""The one error type that reaches the user as a single line and exit status 2."""


class InputError(Exception):
    """Bad input (file, parameter, flag): the message names the file, row or column and what is wrong."""
