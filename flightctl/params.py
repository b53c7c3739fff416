"""Parameters as a schema: default, range, unit and source for each, loaded from TOML.

A parameter file is flat TOML for the airframe (the names of ``conventions.md``), each value
optionally with its plausible range (``range.NAME = [lo, hi]``, drawn by the Monte Carlo), two optional
tables, ``[gains]`` and ``[filters]``, and any number of ``[[effect]]`` tables: model extensions
(docs/measured-data.md) that the simulator and diagnose carry into the base model. ``--params NAME``
also takes the name of a shipped vehicle file (``flightctl/vehicles/NAME.toml``). Anything unknown, mistyped or out of range is refused with
one line that names the key: the program never flies with a bad file.

Where each value comes from (`Params.sources`, written beside it by `dumps`, in every log header): the
schema's source for a default; for a value the file sets, the file, with the file's own comment on
that line when it has one (``M = 1.2  # kg; weighed``); for gains chosen by name, that table of the
paper. A gain set chosen by name (``--gains table4``) replaces the file's ``[gains]`` whole: the flag
wins, and the gains' sources say so.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from flightctl.errors import InputError, number

from flightctl.files import read_text, read_toml, write_atomic
from flightctl.schema import check_range, entry


INERTIA_TOLERANCE = 0.10  # accepted excess of one principal inertia over the sum of the others


def _p(default, unit, lo, hi, source, doc="", log=False):
    """One schema entry (flightctl/schema.py) with its source. `log`: a plausible range of this value is
    drawn uniformly in its logarithm (a time constant whose plausible values span decades)."""
    return entry(default, unit, lo, hi, doc, source=source, log=log)


@dataclass(frozen=True)
class Airframe:
    """The reference airframe (DJI Flame Wheel 450, E600 propulsion), conventions.md."""
    M: float = _p(1.645, "kg", 0.05, 50.0, "paper, Table 2", "total mass")
    l: float = _p(0.2475, "m", 0.02, 2.0, "paper, Table 2", "arm length, centre to motor axis")
    g: float = _p(9.80665, "m/s^2", 9.7, 9.9, "paper, Table 2", "gravity")
    Jxx: float = _p(0.014002764, "kg m^2", 1e-6, 10.0, "paper, Table 2", "roll inertia")
    Jyy: float = _p(0.014267729, "kg m^2", 1e-6, 10.0, "paper, Table 2", "pitch inertia")
    Jzz: float = _p(0.029487252, "kg m^2", 1e-6, 10.0, "paper, Table 2", "yaw inertia")
    Jp: float = _p(2.66838e-4, "kg m^2", 0.0, 0.1, "paper, Table 2", "rotor (motor + propeller) inertia, eq. 19-21")
    gamma1: float = _p(4.86291e-4, "N m/(rad/s)^2", 0.0, 1.0, "paper, Table 2", "quadratic yaw drag, eq. 6")
    gamma2: float = _p(1.22958e-3, "N m", 0.0, 1.0, "paper, Table 2",
                       "bearing friction of the yaw-drag rig, eq. 6; 0 in free flight")
    h1: float = _p(1.49e-3, "N", 1e-7, 1.0, "plausible default (hover at P = 172)", "eq. 26 gain")
    h2: float = _p(120.0, "P units", 0.0, 250.0, "plausible default", "eq. 26 dead zone")
    c1: float = _p(1.47e-5, "N/(rad/s)^2", 1e-9, 1e-2, "plausible default (hover near 5000 RPM)", "eq. 27")
    # g1's range: eq. 28's slope tau / f = (CP / CT) D / (2 pi) (scripts/as_flown.py); CP / CT is below 0.9
    # for any propeller that hovers (a figure of merit CT^1.5 / (sqrt 2 CP) above 0.35, with CT up to
    # 0.2) and D at most rotor_radius' 2 m top: 0.29, rounded up to 0.3. The old top, 1.0, drew 50
    # times the rotors' power at hover: a battery current no pack delivers.
    g1: float = _p(0.020, "N m/N", 0.0, 0.3, "plausible default", "eq. 28 slope")
    g2: float = _p(0.002, "N m", -0.1, 0.1, "plausible default", "eq. 28 offset")
    rotor_radius: float = _p(0.1524, "m", 0.005, 1.0, "12-inch propeller", "for ground effect")
    battery_nominal_v: float = _p(14.8, "V", 1.0, 60.0, "4S LiPo", "voltage of the propeller identification")
    loop_hz: float = _p(450.0, "Hz", 50.0, 2000.0, "paper, sections 3.3 and 4.4.1", "control loop rate")
    esc_pwm_hz: float = _p(449.0, "Hz", 30.0, 450.0, "paper, section 4.4.1", "ESC signal frequency")
    sonar_hz: float = _p(45.0, "Hz", 5.0, 60.0, "paper, section 4.2", "ultrasonic trigger rate")

    def check(self) -> None:
        """Physical consistency beyond the ranges: principal inertias obey the triangle inequality.

        Measured inertias carry error: the paper's own Table 2 has Jzz 4.3 % above Jxx + Jyy (a flat
        frame would have them equal), so a violation of up to INERTIA_TOLERANCE is accepted.
        """
        a, b, c = self.Jxx, self.Jyy, self.Jzz
        for name, lhs, rhs in (("Jzz", a + b, c), ("Jyy", a + c, b), ("Jxx", b + c, a)):
            if lhs * (1 + INERTIA_TOLERANCE) < rhs:
                raise InputError(f"{name}: inertia {rhs:g} kg m^2 is not physical "
                                 f"(a principal inertia cannot exceed the sum of the other two, {lhs:g})")
        if self.esc_pwm_hz > self.loop_hz:
            raise InputError("esc_pwm_hz: the ESC frequency cannot exceed the loop rate")

    @property
    def B(self) -> float:
        """Base thrust per motor, M g / 4 (eq. 25)."""
        return self.M * self.g / 4.0

    @property
    def dt(self) -> float:
        return 1.0 / self.loop_hz


@dataclass(frozen=True)
class Gains:
    """PID gains of eq. 24. Defaults: Table 6 (flight); `TABLE4` keeps the simulation gains."""
    kp_z: float = _p(2.4, "N/m", 0.0, 100.0, "paper, Table 6")
    ki_z: float = _p(0.0, "N/(m s)", 0.0, 100.0, "paper, Table 6")
    kd_z: float = _p(0.14, "N s/m", 0.0, 100.0, "paper, Table 6")
    kp_phi: float = _p(4.48, "N/rad", 0.0, 100.0, "paper, Table 6")
    ki_phi: float = _p(0.0045, "N/(rad s)", 0.0, 100.0, "paper, Table 6")
    kd_phi: float = _p(0.221, "N s/rad", 0.0, 100.0, "paper, Table 6")
    kp_theta: float = _p(4.12, "N/rad", 0.0, 100.0, "paper, Table 6")
    ki_theta: float = _p(0.0045, "N/(rad s)", 0.0, 100.0, "paper, Table 6")
    kd_theta: float = _p(0.13, "N s/rad", 0.0, 100.0, "paper, Table 6")
    kp_psi: float = _p(7.55, "N/rad", 0.0, 100.0, "paper, Table 6")
    ki_psi: float = _p(0.0, "N/(rad s)", 0.0, 100.0, "paper, Table 6")
    kd_psi: float = _p(0.248, "N s/rad", 0.0, 100.0, "paper, Table 6")


TABLE6 = Gains()
TABLE4 = Gains(kp_z=1.9, ki_z=0.0, kd_z=1.6, kp_phi=17.1, ki_phi=0.0, kd_phi=1.3,
               kp_theta=17.2, ki_theta=0.0, kd_theta=1.3, kp_psi=7.7, ki_psi=0.0, kd_psi=2.7)
GAIN_SETS = {"table6": TABLE6, "table4": TABLE4}
GAIN_SOURCES = {"table6": "paper, Table 6", "table4": "paper, Table 4"}


@dataclass(frozen=True)
class Filters:
    """Table 5: every value there is a power-of-two time constant in loop periods."""
    alpha_ema: float = _p(1.0 - math.exp(-1.0 / 128.0), "-", 1e-6, 1.0, "paper, Table 5 (eq. 39, tau = 128 dt)")
    alpha_roll_pitch: float = _p(128.0 / 129.0, "-", 0.0, 1.0, "paper, Table 5 (tau = 128 dt)")
    alpha_yaw: float = _p(64.0 / 65.0, "-", 0.0, 1.0, "paper, Table 5 (tau = 64 dt)")
    tau_tilt_air: float = _p(0.0, "s", 0.0, 600.0,
                             "flightctl (docs/estimator.md): the in-flight accelerometer correction; 0 = off, "
                             "as the base model has no rotor drag, so its accelerometer reads no tilt in flight",
                             "a vehicle with rotor drag sets it long beside M/k (the as-flown file: 8192 dt)")
    tau_rate: float = _p(0.0, "s", 0.0, 1.0,
                         "flightctl (docs/estimator.md): the EMA (eq. 36-38's form) on the body rates the D term "
                         "takes in the flight estimator; 0 = the gyro as the chip delivers it",
                         "the paper's text puts its 128 dt EMA there; the vehicle's rate path is a range "
                         "(the as-flown file)", log=True)


@dataclass(frozen=True)
class Sensors:
    """What the vehicle's frame and rotors add to its IMU's readings in flight, beyond the chip's own
    datasheet noise (sim/world/devices.py `SensorNoise`): the rotors' vibration at each rotor's speed
    and its harmonics on both sensors, and the gyro's broadband part. The simulator reads it; the
    onboard code never does. The defaults are the reference airframe's as the simulator has always
    flown it (the accelerometer's 1/rev only); a vehicle file carries its own, with ranges."""
    accel_vibration: float = _p(0.5, "m/s^2", 0.0, 50.0,
                                "plausible: a 3 g mm imbalance at hover speed on the 1.645 kg frame "
                                "(docs/estimator.md)", "each rotor's 1/rev specific force at hover thrust, "
                                "before the DLPF; it grows with the thrust")
    gyro_vibration: float = _p(0.0, "rad/s", 0.0, 5.0, "none in the reference airframe",
                               "each rotor's 1/rev body rate (roll and pitch) at hover thrust, before the DLPF", log=True)
    harmonic2: float = _p(0.0, "-", 0.0, 5.0, "none in the reference airframe",
                          "the 2/rev (blade-pass, two blades) line's amplitude over the 1/rev's, both sensors")
    harmonic3: float = _p(0.0, "-", 0.0, 5.0, "none in the reference airframe",
                          "the 3/rev line's amplitude over the 1/rev's, both sensors")
    gyro_broadband: float = _p(0.0, "rad/s", 0.0, 5.0, "none in the reference airframe",
                               "the roll and pitch rates' broadband (frame and airflow) noise at hover thrust, "
                               "rms per read; it grows with the thrust", log=True)
    yaw_share: float = _p(0.6, "-", 0.0, 2.0,
                          "paper, sec. 4.4.4: r within 0.006 rad/s where p and q were within 0.01",
                          "the yaw rate's broadband noise over the roll and pitch rates'")
    yaw_lines: float = _p(2.94, "-", 0.0, 10.0,
                          "rigid body: a rotor's imbalance force F at the arm l and the hub height h rocks the "
                          "frame by F h / (Jxx w) in roll and F l / (Jzz w) in yaw, l Jxx / (h Jzz) at h = 4 cm "
                          "(scripts/as_flown.py)",
                          "the yaw rate's rotor lines over the roll and pitch rates'")


@dataclass(frozen=True)
class EffectSpec:
    """A model extension carried by a parameter file (docs/measured-data.md: an identified model grows
    as its errors are found). The onboard code only reads and writes it; the simulator and diagnose
    build the term from its `cause` (their registry checks the name and parameters)."""
    cause: str
    parameters: tuple[tuple[str, float], ...]
    source: str = ""
    ranges: tuple[tuple[str, float, float], ...] = ()   # (parameter, lo, hi): its plausible range


@dataclass(frozen=True)
class Params:
    airframe: Airframe = Airframe()
    gains: Gains = TABLE6
    filters: Filters = Filters()
    effects: tuple[EffectSpec, ...] = ()
    ranges: tuple[tuple[str, float, float], ...] = ()   # airframe (value, lo, hi): `range.NAME = [lo, hi]`
    sensors: Sensors = Sensors()
    # (table, value, lo, hi) of [filters] and [sensors]: `range.NAME = [lo, hi]` inside the table
    table_ranges: tuple[tuple[str, str, float, float], ...] = ()
    # where the values come from (not part of their equality): "" the defaults, "vehicle NAME" or
    # "file PATH"; and (name, source) of every value whose source is not its schema's
    origin: str = field(default="", compare=False)
    sources: tuple[tuple[str, str], ...] = field(default=(), compare=False)

    def source(self, name: str) -> str:
        """Where the value `name` (of the airframe, [gains] or [filters]) comes from."""
        for key, text in self.sources:
            if key == name:
                return text
        for t in (Airframe, Gains, Filters, Sensors):
            for f in dataclasses.fields(t):
                if f.name == name:
                    return f.metadata["source"]
        raise KeyError(name)

    def effect(self, causes: str | tuple[str, ...]) -> EffectSpec | None:
        """The first `[[effect]]` the file carries of the cause (or one of the causes) named, else None."""
        causes = (causes,) if isinstance(causes, str) else causes
        return next((e for e in self.effects if e.cause in causes), None)

    def effect_value(self, cause: str, name: str) -> float:
        """A parameter of an effect the file carries, 0 where it carries none."""
        e = self.effect(cause)
        return float(dict(e.parameters).get(name, 0.0)) if e is not None else 0.0

    def effect_range(self, causes: str | tuple[str, ...], name: str, value: float) -> tuple[float, float]:
        """The range the file gives a parameter of one of `causes` (`range.NAME`), around `value`;
        (value, value) where it gives none."""
        causes = (causes,) if isinstance(causes, str) else causes
        for e in self.effects:
            if e.cause in causes:
                for n, lo, hi in e.ranges:
                    if n == name:
                        return min(lo, value), max(hi, value)
        return value, value

    def digest(self) -> str:
        """A short hash of the values (sha256 of `dumps`, sources left out): two runs with the same
        digest flew the same parameters."""
        return hashlib.sha256(dumps(dataclasses.replace(self, sources=()), plain=True).encode()).hexdigest()[:16]


VEHICLES = Path(__file__).parent / "vehicles"   # shipped parameter files, by name (`--params NAME`)


def schema(cls) -> list[dataclasses.Field]:
    return list(dataclasses.fields(cls))


def _build(cls, table: dict, where: str, base=None):
    base = base if base is not None else cls()
    known = {f.name: f for f in dataclasses.fields(cls)}
    values = {}
    for key, value in table.items():
        name = f"{where}{key}"
        if key not in known:
            raise InputError(f"{name}: unknown parameter (known: {', '.join(sorted(known))})")
        meta = known[key].metadata
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{name}: expected a number, got {type(value).__name__} {_short(value)}")
        v = number(value)
        check_range(name, value if v is None else v, meta, _short(value))
        value = v
        values[key] = value
    return dataclasses.replace(base, **values)


def _short(value) -> str:
    """A value for an error line: never thousands of digits."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:37]}..."


def from_dict(data: dict, gains: Gains | None = None) -> Params:
    """Validate a parsed TOML document. `gains`: a gain set chosen by name, which replaces the
    document's [gains] (validated all the same); None: the document's [gains] over Table 6."""
    data = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}  # never mutate the caller's tables
    tables = {"gains": (Gains, gains or TABLE6), "filters": (Filters, Filters()), "sensors": (Sensors, Sensors())}
    built, table_ranges = {}, []
    for name, (cls, base) in tables.items():
        table = data.pop(name, {})
        if not isinstance(table, dict):
            raise InputError(f"{name}: expected a table [{name}]")
        table = dict(table)
        preset = table.pop("preset", None) if cls is Gains else None
        if preset is not None:
            if not isinstance(preset, str) or preset not in GAIN_SETS:
                raise InputError(f"gains.preset: unknown gain set {preset!r} (known: {', '.join(GAIN_SETS)})")
            base = GAIN_SETS[preset]
        spans = table.pop("range", {}) if cls is not Gains else {}
        built[name] = _build(cls, table, f"{name}.", base)
        table_ranges += [(name, *span) for span in _spans(spans, dataclasses.asdict(built[name]), f"{name}.", cls)]
    if gains is not None:
        built["gains"] = gains
    effects = _effects(data.pop("effect", []))
    ranges = data.pop("range", {})
    airframe = _build(Airframe, data, "")
    airframe.check()
    return Params(airframe=airframe, effects=effects, ranges=_spans(ranges, dataclasses.asdict(airframe), "", Airframe),
                  table_ranges=tuple(table_ranges), **built)


def _spans(ranges, values: dict, where: str, cls=None) -> tuple[tuple[str, float, float], ...]:
    """`range.NAME = [lo, hi]` entries: each around the value of NAME (in `values`), and for an
    airframe value (`cls`) within its schema's limits."""
    if not isinstance(ranges, dict):
        raise InputError(f"{where}range: expected range.NAME = [lo, hi]")
    limits = {f.name: f.metadata for f in dataclasses.fields(cls)} if cls is not None else {}
    spans = []
    for key, span in ranges.items():
        ok = isinstance(span, list) and len(span) == 2 and all(number(v) is not None for v in span)
        if cls is not None and key not in limits:
            raise InputError(f"{where}range.{key}: unknown parameter (known: {', '.join(sorted(limits))})")
        if not ok or key not in values or not float(span[0]) <= float(values[key]) <= float(span[1]) or (
                key in limits and not (limits[key]["lo"] <= float(span[0]) and float(span[1]) <= limits[key]["hi"])):
            raise InputError(f"{where}range.{key}: expected [lo, hi] around the value of {key}, got {_short(span)}")
        spans.append((key, float(span[0]), float(span[1])))
    return tuple(spans)


def _effects(items) -> tuple[EffectSpec, ...]:
    """`[[effect]]` tables: `cause = "name"`, optional `source = "..."`, numeric parameters, and
    optionally each parameter's plausible range, `range.NAME = [lo, hi]` around its value."""
    if not isinstance(items, list):
        raise InputError("effect: expected [[effect]] tables")
    specs = []
    for k, item in enumerate(items, start=1):
        where = f"effect {k}"
        if not isinstance(item, dict):
            raise InputError(f"{where}: expected an [[effect]] table")
        item = dict(item)
        cause, source, ranges = item.pop("cause", None), item.pop("source", ""), item.pop("range", {})
        if not isinstance(cause, str) or not cause:
            raise InputError(f"{where}: cause: a cause name is needed (docs/diagnose.md lists them)")
        if not isinstance(source, str):
            raise InputError(f"{where}: source: expected text")
        for key, value in item.items():
            if number(value) is None:
                raise InputError(f"{where} ({cause}): {key}: expected a finite number, got {_short(value)}")
        spans = _spans(ranges, item, f"{where} ({cause}): ")
        specs.append(EffectSpec(cause, tuple((key, float(v)) for key, v in item.items()), source, spans))
    return tuple(specs)


def resolve(spec: str | Path) -> Path:
    """A parameter file's path, or the name of a shipped vehicle (`paper-as-flown`)."""
    path = Path(spec)
    if path.suffix != ".toml" and not path.exists() and (VEHICLES / f"{spec}.toml").is_file():
        return VEHICLES / f"{spec}.toml"
    return path


def shipped() -> list[str]:
    """The names of the shipped vehicles (`--params NAME`)."""
    return sorted(f.stem for f in VEHICLES.glob("*.toml"))


def gain_set_name(gains: Gains) -> str | None:
    return next((name for name, g in GAIN_SETS.items() if g == gains), None)


_SOURCE_LINE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=[^#]*#\s*(.*)$")


def _file_sources(text: str, data: dict, origin: str) -> dict[str, str]:
    """The source of each airframe, [gains] and [filters] value the file sets: the origin, and the
    comment on its line after the unit (`dumps` writes `# unit; source`) when there is one."""
    known = {f.name for t in (Airframe, Gains, Filters) for f in dataclasses.fields(t)}
    keys = {k for k, v in data.items() if not isinstance(v, (dict, list))}
    for table in ("gains", "filters"):
        if isinstance(data.get(table), dict):
            keys |= set(data[table]) - {"preset"}
    out = {}
    section = ""
    for line in text.splitlines():
        head = line.strip()
        if head.startswith("["):
            section = head.strip("[] ")
            continue
        m = _SOURCE_LINE.match(line)
        if m and m.group(1) in keys & known and section in ("", "gains", "filters"):
            note = m.group(2).split(";", 1)[-1].strip()
            out[m.group(1)] = f"{origin}: {note}" if note else origin
    for key in (keys & known) - set(out):
        out[key] = origin
    preset = data.get("gains", {}).get("preset") if isinstance(data.get("gains"), dict) else None
    if preset in GAIN_SOURCES:
        for f in dataclasses.fields(Gains):
            out.setdefault(f.name, f"{GAIN_SOURCES[preset]} ({origin}: gains.preset)")
    return out


def load(path: str | Path | None, gains: Gains | None = None) -> Params:
    """Load and validate a parameter file; None gives the shipped reference airframe. `gains`: a gain
    set chosen by name (`--gains`), which replaces the file's [gains]."""
    chosen = {}
    name = gain_set_name(gains) if gains is not None else None
    if gains is not None and gains != TABLE6:
        what = f"{GAIN_SOURCES[name]} (--gains {name})" if name else "the gains given"
        chosen = {f.name: what for f in dataclasses.fields(Gains)}
    if path is None:
        return dataclasses.replace(from_dict({}, gains), sources=tuple(chosen.items()))
    spec, path = path, resolve(path)
    if not path.exists():
        raise InputError(f"{spec}: neither a parameter file nor a shipped vehicle (shipped: {', '.join(shipped())})")
    text = read_text(path)                  # a regular file, UTF-8 (a pipe or a device refused unread)
    if path.suffix.lower() != ".toml":
        raise InputError(f"{spec}: a parameter file is TOML and named .toml (shipped vehicles: {', '.join(shipped())})")
    data = read_toml(path, text)
    try:
        params = from_dict(data, gains)
    except InputError as e:
        raise InputError(f"{path}: {e}") from None
    origin = f"vehicle {path.stem}" if path.parent == VEHICLES else f"file {path}"
    sources = _file_sources(text, data, origin)
    if gains is not None:
        gain_names = {f.name for f in dataclasses.fields(Gains)}
        sources = {k: v for k, v in sources.items() if k not in gain_names}
        file_gains = isinstance(data.get("gains"), dict) and data["gains"]
        what = f"{GAIN_SOURCES[name]} (--gains {name}" if name else "the gains given ("
        for f in dataclasses.fields(Gains):
            sources[f.name] = what + (f", replacing the [gains] of {origin})" if file_gains else ")")
    return dataclasses.replace(params, origin=origin, sources=tuple(sources.items()))


def dumps(params: Params, sources: dict[str, str] | None = None, tables=("gains", "filters", "sensors"),
          plain: bool = False) -> str:
    """TOML text of a parameter set, with unit and source of each value as comments (`sources` over
    the parameters' own, `Params.source`). A vehicle file leaves out [gains] so that `--gains` chooses
    them. `plain`: the values only, no comments."""
    sources = sources or {}
    lines = [] if plain else ["# flightctl parameter file (SI units; see docs/conventions.md)"]

    def emit(obj):
        for f in dataclasses.fields(obj):
            if plain:
                lines.append(f"{f.name} = {getattr(obj, f.name)!r}")
                continue
            source = sources.get(f.name) or params.source(f.name)
            lines.append(f"{f.name} = {getattr(obj, f.name)!r}  # {f.metadata['unit']}; {source}")

    emit(params.airframe)
    lines += [f"range.{k} = [{lo!r}, {hi!r}]" for k, lo, hi in params.ranges]
    for name in tables:
        lines.append(f"\n[{name}]")
        emit(getattr(params, name))
        lines += [f"range.{k} = [{lo!r}, {hi!r}]" for table, k, lo, hi in params.table_ranges if table == name]
    for e in params.effects:
        lines.append("\n[[effect]]")
        lines.append(f"cause = {json.dumps(e.cause)}")
        lines += [f"{k} = {v!r}" for k, v in e.parameters]
        lines += [f"range.{k} = [{lo!r}, {hi!r}]" for k, lo, hi in e.ranges]
        if e.source and not plain:
            lines.append(f"source = {json.dumps(e.source)}")
    return "\n".join(lines) + "\n"


def update_file(path: str | Path, values: dict[str, float], source: str) -> Params:
    """Write fitted airframe values into a parameter file (created if missing), validated first."""
    path = Path(path)
    data = read_toml(path) if path.exists() else {}
    data.update(values)
    params = from_dict(data)
    write_atomic(path, dumps(params, {k: source for k in values}))
    return params
