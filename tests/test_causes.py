"""The registry of causes (flightctl.sim.causes) against the contract's table of causes in
measured-data.md: the same names and parameter names (with their units), and each cause's effect
and diagnose candidate consistent with each other."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from flightctl.sim import causes
from flightctl.sim.identify.diagnose.candidate import Candidate
from flightctl.sim.world.model import Effect
from real import need

SPEC = Path(__file__).resolve().parents[2] / "shared" / "spec" / "measured-data.md"


def _unit(text: str) -> str:
    return text.replace("·", " ").replace("–", "-").strip()


def spec_table() -> dict[str, dict[str, str | None]]:
    """{cause: {parameter: unit or None}} from the table 'Candidate extensions: names and parameters'."""
    text = need(SPEC).read_text(encoding="utf-8")   # a missing contract fails in CI
    section = text.split("## Candidate extensions", 1)[1].split("\n## ", 1)[0]
    rows = section.split("|---|---|---|", 1)[1].strip().splitlines()   # the body, after the header
    table = {}
    for line in rows:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        name = cells[0].strip("`")
        params = {}
        # groups like "`dx`, `dy` (m)", "`tau` (s)", "`motor` (1–4), `scale`"
        for group in re.finditer(r"((?:`\w+`(?:,\s*)?)+)\s*(?:\(([^)]*)\))?", cells[2]):
            for p in re.findall(r"`(\w+)`", group.group(1)):
                params[p] = _unit(group.group(2)) if group.group(2) else None
        table[name] = params
    return table


def test_the_spec_table_is_read():
    table = spec_table()
    assert table["none"] == {}
    assert table["com_offset"] == {"dx": "m", "dy": "m"}
    assert table["motor_weak"] == {"motor": "1-4", "scale": None}


def test_registry_has_the_causes_of_the_contract_in_its_order():
    table = spec_table()
    assert list(causes.CAUSES) == [c for c in table if c != "none"]


def test_registry_parameters_and_units_match_the_contract():
    table = spec_table()
    for name, cause in causes.CAUSES.items():
        assert list(cause.parameters) == list(table[name]), name
        for p, unit in table[name].items():
            if unit is not None:
                assert cause.parameters[p].unit == unit, (name, p)


def test_each_cause_pairs_its_effect_and_its_candidate():
    for name, cause in causes.CAUSES.items():
        assert issubclass(cause.effect, Effect) and issubclass(cause.candidate, Candidate)
        assert cause.effect.cause == name and cause.candidate.effect is cause.effect
        assert cause.doc and "\n" not in cause.doc and cause.doc.endswith(".")
        for p in cause.parameters.values():
            assert p.lo <= p.hi


def test_make_builds_each_effect_within_its_ranges_and_refuses_outside():
    from flightctl.errors import InputError
    for name, cause in causes.CAUSES.items():
        mid = {p: (s.lo + s.hi) / 2 if name != "motor_weak" or p != "motor" else 2.0
               for p, s in cause.parameters.items()}
        e = causes.make(name, **mid)
        assert type(e) is cause.effect and e.parameters == mid
        assert causes.parse(repr(e)).parameters == pytest.approx(mid)
        p, s = next(iter(cause.parameters.items()))
        with pytest.raises(InputError, match="out of range"):
            causes.make(name, **{**mid, p: s.hi + 1.0})
