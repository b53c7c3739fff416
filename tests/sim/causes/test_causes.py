"""The registry of causes (flightctl.sim.causes) against the contract's table of causes in the
specification's measured-data.md (../shared/spec/ beside the checkout; docs/measured-data.md carries its
text), followed by the project's own extensions, each in the table of docs/diagnose.md ("Causes beyond
the contract"): the same names in the same order and the same parameter names (with their units), and
each cause's effect and diagnose candidate consistent with each other."""
from __future__ import annotations

import re

import pytest

from flightctl.sim import causes
from flightctl.sim.diagnose.candidate import Candidate
from flightctl.sim.world.model import Effect
from helpers.real import need
from helpers.paths import ROOT

SPEC = ROOT.parent / "shared" / "spec" / "measured-data.md"
DOC = ROOT / "docs" / "diagnose.md"


def _unit(text: str) -> str:
    return text.replace("·", " ").replace("–", "-").strip()


def cause_table(text: str, heading: str) -> dict[str, dict[str, str | None]]:
    """{cause: {parameter: unit or None}} from the first table under the `## heading...` section:
    its first cell the cause, its last the parameters."""
    section = text.split(f"## {heading}", 1)[1].split("\n## ", 1)[0]
    rows = section.split("|---|---|---|", 1)[1].strip().splitlines()   # the body, after the header
    table = {}
    for line in rows:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        name = cells[0].strip("`")
        params = {}
        # groups like "`dx`, `dy` (m)", "`tau` (s)", "`motor` (1–4), `scale`"
        for group in re.finditer(r"((?:`\w+`(?:,\s*)?)+)\s*(?:\(([^)]*)\))?", cells[-1]):
            for p in re.findall(r"`(\w+)`", group.group(1)):
                params[p] = _unit(group.group(2)) if group.group(2) else None
        table[name] = params
    return table


def spec_table() -> dict[str, dict[str, str | None]]:
    """The contract's causes, from the table 'Candidate extensions: names and parameters'."""
    return cause_table(need(SPEC).read_text(encoding="utf-8"), "Candidate extensions")   # a missing contract fails in CI


def extension_table() -> dict[str, dict[str, str | None]]:
    """The project's own causes, from docs/diagnose.md's table 'Causes beyond the contract'."""
    return cause_table(DOC.read_text(encoding="utf-8"), "Causes beyond the contract")


def all_causes() -> dict[str, dict[str, str | None]]:
    return {**{c: p for c, p in spec_table().items() if c != "none"}, **extension_table()}


def test_the_spec_table_is_read():
    table = spec_table()
    assert table["none"] == {}
    assert table["com_offset"] == {"dx": "m", "dy": "m"}
    assert table["motor_weak"] == {"motor": "1-4", "scale": None}


def test_the_extension_table_is_read_and_extends_the_contract():
    ext, spec = extension_table(), spec_table()
    assert ext and ext["gyro_lag"] == {"tau": "s"}
    assert not set(ext) & set(spec), "a cause of the contract is not an extension"


def test_registry_has_the_causes_of_the_contract_in_its_order_then_the_extensions():
    assert list(causes.CAUSES) == list(all_causes())
    assert causes.EXTENSIONS == tuple(extension_table())


def test_registry_parameters_and_units_match_the_tables():
    table = all_causes()
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


def test_a_cause_declared_in_one_module_is_seen_by_the_chain_and_the_compiled_plant():
    """A cause defined here, in one place, with its twin, timing, look-alikes and compiled wrench drawn at
    random: once registered, diagnose's chain (verdict.py) and the compiled plant (compiled.py) answer
    from its declarations, and without it they no longer know it."""
    import numpy as np
    from flightctl.params import Airframe
    from flightctl.sim.diagnose import verdict
    from flightctl.sim.diagnose.candidate import GridCandidate
    from flightctl.sim.world import compiled
    from flightctl.sim.world.model import Model, Parameter

    rng = np.random.default_rng(4701)
    others = list(causes.CAUSES)
    partner = str(rng.choice(others))
    alikes = tuple(str(c) for c in rng.choice(others, size=2, replace=False))
    timing = bool(rng.integers(2))
    k, hook = float(rng.uniform(0.1, 5.0)), str(rng.choice(["drag", "inflow"]))
    q_name = {"drag": "k_drag", "inflow": "k_in"}[hook]

    class Sticky(Effect):
        """A drag the test invents."""
        cause = "sticky_test_cause"
        required = {"k": Parameter("N s/m", 0.0, 10.0)}
        compiled, compiled_hook = True, hook

        def compiled_q(self):
            return {q_name: self.parameters["k"], "B": 1.0}

    class StickyFit(GridCandidate):
        effect = Sticky
        twin, times_actuation, lookalikes = partner, timing, alikes

    assert "sticky_test_cause" not in compiled.COMPILED_CAUSES
    assert verdict.twin("sticky_test_cause") is None
    causes.register(StickyFit)
    try:
        assert verdict.twin("sticky_test_cause") == partner
        assert verdict.times_actuation("sticky_test_cause") is timing
        assert verdict.lookalikes("sticky_test_cause") == alikes
        assert "sticky_test_cause" in compiled.COMPILED_CAUSES
        codes, q = compiled.layout(Model(Airframe(), (Sticky(k=k),)))
        assert codes.tolist() == [compiled.HOOKS[hook]]
        assert q[compiled.Q_NAMES[q_name]] == k
        assert causes.make("sticky_test_cause", k=k).parameters == {"k": k}
        with pytest.raises(ValueError):
            causes.register(StickyFit)
    finally:
        del causes.CAUSES["sticky_test_cause"]
    assert verdict.twin("sticky_test_cause") is None and verdict.lookalikes("sticky_test_cause") == ()
    assert "sticky_test_cause" not in compiled.COMPILED_CAUSES


def test_the_declarations_of_the_causes_are_consistent():
    """Twins name each other, look-alikes are mutual, and every cause declared is registered."""
    for name in causes.CAUSES:
        t = causes.twin(name)
        if t is not None:
            assert t in causes.CAUSES and causes.twin(t) == name, name
        for alt in causes.lookalikes(name):
            assert alt in causes.CAUSES and name in causes.lookalikes(alt), (name, alt)
    assert any(causes.times_actuation(c) for c in causes.CAUSES)
