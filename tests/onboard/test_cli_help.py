"""Every option of every `flightctl` command says what it does (issue 19: `--no-plot`, `--quiet`,
`--profile`, `--link`, `--mode` had no help), and no help text points at an issue number instead of
saying it. The parsers are the ones `main` builds: `parse_args` is intercepted to collect them."""
from __future__ import annotations

import argparse
import re

import pytest

from flightctl import cli


class _Built(Exception):
    pass


def _parsers(monkeypatch, argv: list[str]) -> list[argparse.ArgumentParser]:
    """The parser `flightctl argv...` builds, with its subcommands' parsers."""
    built = []

    def capture(self, args=None, namespace=None):
        built.append(self)
        raise _Built

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", capture)
    monkeypatch.setattr(argparse.ArgumentParser, "parse_known_args", capture)
    try:
        cli.main(argv)
    except _Built:
        pass
    out, todo = [], list(built)
    while todo:
        p = todo.pop()
        out.append(p)
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo += list(dict.fromkeys(action.choices.values()))
    return out


INVOCATIONS = [[name] for name in cli.COMMANDS] + [["sim", "faults"]]


@pytest.mark.parametrize("argv", INVOCATIONS, ids=" ".join)
def test_every_option_has_a_help_text_without_an_issue_number(monkeypatch, argv):
    parsers = _parsers(monkeypatch, argv)
    assert parsers, f"flightctl {' '.join(argv)} built no parser"
    missing = [f"{p.prog} {'/'.join(a.option_strings) or a.dest}" for p in parsers for a in p._actions
               if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))
               and not (a.help and a.help.strip())]
    assert not missing, f"options without help: {missing}"
    texts = [p.description or "" for p in parsers] + [a.help or "" for p in parsers for a in p._actions]
    assert not [t for t in texts if re.search(r"\(issue \d+\)", t)]
