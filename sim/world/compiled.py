"""The simulated world compiled by numba where it is installed (the `fast` extra): the plant's step
and forces (here; `period` is the plant's one call a period) and the MPU-9250's burst registers
(`sim.world.imu.chip_frame`), each function from its one plain-Python source: `compiled_copy(fn,
name=dependency, ...)` compiles a copy of `fn` whose global names of other plain functions are bound
to their compiled copies, so that the plain function stays plain (arrays in the batched simulator,
and everywhere without numba). Nothing on the vehicle imports this: the onboard code is plain Python.

`FLIGHTCTL_JIT=0` in the environment turns compilation off (a comparison, or a machine where numba
misbehaves); `enabled()` says whether it is on. numba is in the default install where it has wheels
(pyproject.toml); where it is missing, the plain path is said once on stderr. Compiled code is cached (numba's `cache=True`): the
first flight of a fresh install compiles for a few seconds, later ones load it. numba's cache checks
only each function's own file, not the files of the functions it calls or of the constants it reads:
the cache's folder (sim/__pycache__/numba-<hash>, unless NUMBA_CACHE_DIR is set) is named by a hash
of every such file, so that a change to any of them compiles afresh. The folder must be one only
this user can write (flightctl/cachedir.py: made with mode 0700, not a link, owned by this user, no
write bit for others), since numba loads the machine code it finds there: where it is not (a package
installed for another user, a service user without a home, a NUMBA_CACHE_DIR of another user's), the
cache goes to the user's cache folder, else to the temporary folder under a name with the user's id
(predictable, so a folder planted there by another user is refused), else nowhere (every process
compiles afresh), said once on stderr.
"""
from __future__ import annotations

import functools
import hashlib
import os
import sys
import tempfile
import types
from pathlib import Path
from math import copysign, cos, sin, sqrt

import numpy as np

from flightctl.cachedir import own_folder
from flightctl.physics import esc_command, rotor_speed, rotor_torque, thrust_from_command, thrust_from_speed
from flightctl.sim.causes.motor_dynamics import FULL_P, SPIN, reaction_torque, speed_rate
from flightctl.sim.causes.rotor_drag import drag_wrench
from flightctl.sim.causes.rotor_inflow import airflow, inflow_wrench
from flightctl.sim.world.model import N_RIGID, aggregate, body_velocity, rigid_derivative, rotation_from_trig


@functools.cache
def enabled() -> bool:
    """numba is installed and not turned off (and its cache folder set, before its import)."""
    if os.environ.get("FLIGHTCTL_JIT", "1") == "0":
        return False
    if "numba" not in sys.modules:
        digest = source_digest()
        given = os.environ.get("NUMBA_CACHE_DIR")
        folder, passed = own_folder(cache_candidates(digest, given), "NUMBA_CACHE_DIR" if given else None)
        global CACHE
        said = os.environ.get(CACHE_SAID)     # once: a pool's workers inherit the variable
        os.environ[CACHE_SAID] = "1"
        if folder is None:
            CACHE = False
            if not said:
                print(f"flightctl: no folder only this user can write for the compiled simulator's cache "
                      f"({'; '.join(passed)}): it compiles afresh in this process", file=sys.stderr)
        else:
            if passed and not said:
                print(f"flightctl: the compiled simulator's cache is in {folder} ({'; '.join(passed)})",
                      file=sys.stderr)
            os.environ["NUMBA_CACHE_DIR"] = str(folder)
    try:
        import numba  # noqa: F401
    except ImportError:
        if not os.environ.get(PLAIN_SAID):     # once: a pool's workers inherit the variable
            os.environ[PLAIN_SAID] = "1"
            print("flightctl: numba is not installed here: the simulated world runs as plain Python, several "
                  "times slower (python3 -m pip install numba, where it has wheels, compiles it)", file=sys.stderr)
        return False
    return True


PLAIN_SAID = "FLIGHTCTL_PLAIN_SAID"   # set once the plain-Python fallback has been said, for child processes


CACHE = True        # numba's cache=True, unless no folder only this user can write is found
CACHE_SAID = "FLIGHTCTL_CACHE_SAID"   # set once the cache's folder has been chosen, for child processes


def source_digest() -> str:
    """The hash of every file the compiled code depends on: it names the cache's folder (the module's
    docstring)."""
    import flightctl.drivers.mpu9250_regs
    import flightctl.physics
    here = Path(__file__).parent
    compiled_files = [Path(flightctl.physics.__file__), Path(flightctl.drivers.mpu9250_regs.__file__)]
    compiled_files += [here / name for name in ("model.py", "compiled.py", "imu.py")]
    from flightctl.sim.causes import CAUSES      # the causes whose wrench the compiled plant carries (their hooks)
    compiled_files += sorted(Path(sys.modules[c.effect.__module__].__file__) for c in CAUSES.values()
                             if c.effect.compiled and c.effect.compiled_hook is not None)
    compiled_files += [here.parent / "sweeps" / f"{name}.py" for name in ("twin_controller", "twin_loop", "twin_world", "pcg64")]
    compiled_files += [Path(sys.modules["flightctl"].__file__).parent / name for name in (
        "control/estimator.py", "control/mixer.py", "control/landing.py", "control/controller.py", "loop.py",
        "safety.py", "drivers/hcsr04.py")]
    compiled_files += [here / name for name in ("devices.py", "plant.py")]
    return hashlib.sha1(b"".join(path.read_bytes() for path in compiled_files)).hexdigest()[:12]


def cache_candidates(digest: str, given: str | None = None, uid: int | None = None) -> list[Path]:
    """Where numba's cache may go, in order: NUMBA_CACHE_DIR where the user gives it, the package's
    own sim/__pycache__, the user's cache folder, the temporary folder (a name with this user's id:
    predictable, so it is used only if it is this user's own, flightctl/cachedir.py)."""
    here = Path(__file__).parent
    user = Path(os.environ.get("XDG_CACHE_HOME") or Path(os.path.expanduser("~")) / ".cache")
    uid = uid if uid is not None else os.geteuid() if hasattr(os, "geteuid") else 0
    return ([Path(given)] if given else []) + [here / "__pycache__" / f"numba-{digest}",
                                                 user / "flightctl" / f"numba-{digest}",
                                                 Path(tempfile.gettempdir()) / f"flightctl-numba-{uid}-{digest}"]


def compiled_copy(fn, allocates: bool = False, **dependencies):
    """`fn` compiled in nopython mode, its globals named in `dependencies` replaced (the compiled
    copies of the plain functions it calls); None when compilation is off.

    `allocates`: fn makes an array or returns one, and keeps numba's reference counting. Every other
    copy compiles without it (numba's `_nrt=False`): the arrays it is given are its caller's, borrowed
    for the call, so that no call in the batch's inner loop counts references (an atomic increment and
    decrement per array argument per call: a third of the loop's time with it).

    Every copy is inlined where it is called (numba's `forceinline`: LLVM's `alwaysinline`), so that a
    call passes no arrays as their seven words each and no status through memory: a quarter of the
    batch's time without it. Inlining moves no arithmetic (no fast-math: LLVM neither reassociates
    nor contracts), so the results are the plain function's to the bit (tests/sim/world/test_compiled.py)."""
    if not enabled():
        return None
    import numba
    copy = rebound(fn, **dependencies)
    return numba.njit(cache=CACHE, nogil=True, forceinline=True, **({} if allocates else {"_nrt": False}))(copy)


def rebound(fn, **dependencies):
    """A copy of the plain function `fn` whose global names in `dependencies` are bound to other
    functions (`compiled_copy` compiles such a copy)."""
    g = dict(fn.__globals__)
    g.update(dependencies)
    copy = types.FunctionType(fn.__code__, g, fn.__name__, fn.__defaults__, fn.__closure__)
    copy.__qualname__, copy.__module__, copy.__doc__ = fn.__qualname__, fn.__module__, fn.__doc__
    return copy


# The effects the compiled plant carries are those whose class says so (`Effect.compiled`, in each cause's
# module), by their wrench hooks' codes (`layout`, from the effect's `compiled_hook`); a model with any
# other effect integrates in plain Python (Plant._rk4).
INFLOW, REACTION, DRAG = 1, 2, 3
HOOKS = {"inflow": INFLOW, "reaction": REACTION, "drag": DRAG}
# q: the parameters of `stage`, by index
# (_ROOT: sqrt(c1 / B), a rotor's `airflow_root` per rad/s of its speed; _WEAK, _SCALE: motor_weak's
# rotor, 0-3, -1 without one, and its scale; _P_FULL: the ESC's full throttle, motor_dynamics' `p_full`)
_C1, _G1, _G2, _L, _TAU, _DOWN, _K_IN, _B, _HUB, _K_DRAG, _YAW, _H1, _H2, _JP, _ROOT, _WEAK, _SCALE, _P_FULL, _RIGID = \
    range(19)
# the names by which an effect's `compiled_q` gives its entries of q
Q_NAMES = {"tau": _TAU, "tau_down": _DOWN, "k_in": _K_IN, "B": _B, "hub": _HUB, "k_drag": _K_DRAG, "yaw": _YAW,
           "weak": _WEAK, "scale": _SCALE, "p_full": _P_FULL}
N_OUT = 18   # `period`'s output: the fields of `Forces` (f, tau, force, torque, w) one after another


def __getattr__(name):
    if name == "COMPILED_CAUSES":     # read at each use: a cause registered later is in it
        from flightctl.sim.causes import CAUSES
        return tuple(n for n, c in CAUSES.items() if c.effect.compiled)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def layout(model):
    """(the wrench codes in the model's order, the parameters q) of a model whose effects the compiled
    plant carries (`Effect.compiled`, each at most once; the base model has none), else None."""
    laid = _layout(model)
    return None if laid is None else (laid[0], np.array(laid[1], dtype=float))


def layout_rows(model, n: int):
    """`layout` of a model whose parameters (its airframe's, its effects') may be (n,) arrays, one value
    per vehicle (the batched simulator, sim/sweeps/twin_loop.py): q as (n, len(q)), a row per vehicle."""
    laid = _layout(model)
    if laid is None:
        return None
    return laid[0], np.stack([np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in laid[1]], axis=1)


def _layout(model):
    """(codes, q as a list of values) of `layout`."""
    causes = [e.cause for e in model.effects]
    if len(set(causes)) < len(causes) or not all(e.compiled for e in model.effects):
        return None
    a = model.a
    B = a.M * a.g / 4.0
    q = [a.c1, a.g1, a.g2, a.l, 0.0, 0.0, 0.0, B, 0.0, 0.0, 0.0, a.h1, a.h2, a.Jp, (a.c1 / B) ** 0.5, -1.0, 1.0,
         FULL_P]
    codes = []
    for e in model.effects:
        entries = e.compiled_q()
        if entries is None:
            return None
        for name, v in entries.items():
            q[Q_NAMES[name]] = v
        if e.compiled_hook is not None:
            codes.append(HOOKS[e.compiled_hook])
    return np.array(codes, dtype=np.int64), q + list(model.rigid_constants)


def work(n: int) -> np.ndarray:
    """The scratch array of the functions below for a state of n entries: RK4's four stages and its
    trial state (n each, `rk4`'s offsets), then the attitude `attitude_trig` remembers (none yet)."""
    wk = np.zeros(5 * n + _TRIG)
    wk[5 * n:5 * n + 3] = np.nan
    return wk


_TRIG = 9   # `work`'s last entries: phi, theta, psi and their sines and cosines


def attitude_trig(x, xo, wk):
    """(sin phi, cos phi, sin theta, cos theta, sin psi, cos psi) at the state x[xo:], remembered with
    the angles in `work`'s last entries: an RK4 step's first stage is at the state whose forces were
    asked last (the chip's, the floor's), so that each step computes three of them fewer."""
    m = wk.shape[0] - _TRIG
    phi, theta, psi = x[xo + 6], x[xo + 7], x[xo + 8]
    if not (phi == wk[m] and theta == wk[m + 1] and psi == wk[m + 2] and copysign(1.0, phi) == copysign(1.0, wk[m])
            and copysign(1.0, theta) == copysign(1.0, wk[m + 1]) and copysign(1.0, psi) == copysign(1.0, wk[m + 2])):
        wk[m], wk[m + 1], wk[m + 2] = phi, theta, psi
        wk[m + 3], wk[m + 4], wk[m + 5], wk[m + 6] = sin(phi), cos(phi), sin(theta), cos(theta)
        wk[m + 7], wk[m + 8] = sin(psi), cos(psi)
    return wk[m + 3], wk[m + 4], wk[m + 5], wk[m + 6], wk[m + 7], wk[m + 8]


def commanded(P1, P2, P3, P4, q):
    """The commanded thrusts (eq. 26) and speeds (eq. 27) of the command values P1..P4: (f1, f2, f3, f4,
    w1, w2, w3, w4), `rotors`' cmd."""
    h1, h2, c1, top = q[_H1], q[_H2], q[_C1], q[_P_FULL]
    f1, f2 = thrust_from_command(esc_command(P1, top), h1, h2), thrust_from_command(esc_command(P2, top), h1, h2)
    f3, f4 = thrust_from_command(esc_command(P3, top), h1, h2), thrust_from_command(esc_command(P4, top), h1, h2)
    return f1, f2, f3, f4, rotor_speed(f1, c1), rotor_speed(f2, c1), rotor_speed(f3, c1), rotor_speed(f4, c1)


def rotors(x, xo, cmd, codes, q, Rm, xdot, do):
    """`Model._forces` of a model laid out by `layout` (the same functions in the same order): the
    rotors' thrusts f and torques tau, the effects' body force F and torque T, the rotors' speeds w (the
    order of `Forces`, each a tuple), at the state x[xo:] with the rotation Rm (`rotation_from_trig`),
    cmd the commanded thrusts and speeds (`commanded`); the rotor states' derivatives are written into
    xdot[do + N_RIGID:]. Offsets into arrays and tuples of floats, never a new array or view: nothing
    for numba's reference counting in the batch's inner loop. Each rotor's speed is known without a
    root: its state (motor_dynamics; eq. 27 inverted of eq. 27's thrust is |Omega|) or the commanded
    speed, and so is the airflow terms' `airflow_root`, Omega sqrt(c1 / B)."""
    c1 = q[_C1]
    if q[_TAU] > 0.0:          # motor_dynamics: the rotor's speed is a state
        r = xo + N_RIGID
        spin_up = rotor_rates(x, r, cmd, q, xdot, do + N_RIGID)
        f = (thrust_from_speed(x[r], c1), thrust_from_speed(x[r + 1], c1), thrust_from_speed(x[r + 2], c1),
             thrust_from_speed(x[r + 3], c1))
        w = (abs(x[r]), abs(x[r + 1]), abs(x[r + 2]), abs(x[r + 3]))
    else:
        spin_up = 0.0
        f, w = (cmd[0], cmd[1], cmd[2], cmd[3]), (cmd[4], cmd[5], cmd[6], cmd[7])
    g1, g2 = q[_G1], q[_G2]
    tau4 = (rotor_torque(f[0], g1, g2), rotor_torque(f[1], g1, g2), rotor_torque(f[2], g1, g2),
            rotor_torque(f[3], g1, g2))
    if q[_WEAK] >= 0.0:        # motor_weak's `scale` hook (Model._forces): its rotor's thrust and torque times
        m, s = q[_WEAK], q[_SCALE]     # the scale, its speed eq. 27's of the thrust scaled
        s1, s2, s3, s4 = (s if m == 0.0 else 1.0), (s if m == 1.0 else 1.0), (s if m == 2.0 else 1.0), \
            (s if m == 3.0 else 1.0)
        f = (f[0] * s1, f[1] * s2, f[2] * s3, f[3] * s4)
        tau4 = (tau4[0] * s1, tau4[1] * s2, tau4[2] * s3, tau4[3] * s4)
        w = (w[0] * sqrt(s1), w[1] * sqrt(s2), w[2] * sqrt(s3), w[3] * sqrt(s4))
    vb = body_velocity(Rm, x[xo + 3], x[xo + 4], x[xo + 5])
    k = q[_ROOT]
    r1, r2, r3, r4 = w[0] * k, w[1] * k, w[2] * k, w[3] * k
    running = airflow(r1, r2, r3, r4) if codes.shape[0] else 4.0
    Fx = Fy = Fz = Tx = Ty = Tz = 0.0
    for code in codes:
        if code == INFLOW:
            dz, dx, dy = inflow_wrench(r1, r2, r3, r4, q[_K_IN], q[_L], q[_HUB], running, vb[2], x[xo + 9], x[xo + 10])
            Fz += dz
            Tx += dx
            Ty += dy
        elif code == REACTION:
            Tz += reaction_torque(q[_JP], spin_up)
        else:
            dx, dy, dz = drag_wrench(q[_K_DRAG], q[_YAW], running, r1 + r2 + r3 + r4, vb[0], vb[1], x[xo + 11])
            Fx += dx
            Fy += dy
            Tz += dz
    return f, tau4, (Fx, Fy, Fz), (Tx, Ty, Tz), w


def rotor_rates(x, r, cmd, q, xdot, do):
    """motor_dynamics' rotor states x[r:r + 4]: each speed's rate toward the commanded speed (cmd,
    `commanded`) into xdot[do:do + 4]; their spin-up sum s_i dOmega_i/dt (eq. 9's sense)."""
    tau, down = q[_TAU], q[_DOWN]
    d1, d2 = speed_rate(cmd[4], x[r], tau, down), speed_rate(cmd[5], x[r + 1], tau, down)
    d3, d4 = speed_rate(cmd[6], x[r + 2], tau, down), speed_rate(cmd[7], x[r + 3], tau, down)
    xdot[do], xdot[do + 1], xdot[do + 2], xdot[do + 3] = d1, d2, d3, d4
    spin_up = SPIN[0] * d1
    spin_up += SPIN[1] * d2
    spin_up += SPIN[2] * d3
    spin_up += SPIN[3] * d4
    return spin_up


def forces(x, cmd, codes, q, wk):
    """`rotors` at the state x for the commanded thrusts and speeds cmd (`commanded`; `Model.forces`);
    wk: `work` (the rotor states' derivatives go to its first stage)."""
    return rotors(x, 0, cmd, codes, q, rotation_from_trig(*attitude_trig(x, 0, wk)), wk, 0)


def stage(x, xo, cmd, codes, q, xdot, do, ground):
    """`Model.f` of a model laid out by `layout` at the state x[xo:xo + n]: `rotors`, `aggregate` and
    `rigid_derivative`, into xdot[do:do + n] (xdot: `work`, whose attitude it remembers); on the floor (`ground`) the
    rotor states' only (the rigid
    body's stay put, and nothing of it enters the rotors' rates)."""
    if ground:
        if q[_TAU] > 0.0:
            rotor_rates(x, xo + N_RIGID, cmd, q, xdot, do + N_RIGID)
        return
    sf, cf, st, ct, sp, cp = attitude_trig(x, xo, xdot)
    f, tau, F, T, w = rotors(x, xo, cmd, codes, q, rotation_from_trig(sf, cf, st, ct, sp, cp), xdot, do)
    agg = aggregate(f[0], f[1], f[2], f[3], tau[0], tau[1], tau[2], tau[3], w[0], w[1], w[2], w[3],
                    F[0], F[1], F[2], T[0], T[1], T[2], q[_L])
    r = _RIGID
    d = rigid_derivative(x[xo + 3], x[xo + 4], x[xo + 5], sf, cf, st, ct, sp, cp, x[xo + 9], x[xo + 10], x[xo + 11],
                         agg[0], agg[1], agg[2], agg[3], agg[4], agg[5], agg[6], q[r], q[r + 1], q[r + 2], q[r + 3],
                         q[r + 4], q[r + 5], q[r + 6], q[r + 7])
    for i in range(N_RIGID):
        xdot[do + i] = d[i]


def rk4(x, cmd, codes, q, h, wk, ground):
    """One classical RK4 step of `stage` with the input held (`Plant._rk4`'s scheme, element by
    element as numpy evaluates it): the new state in wk[4 n:5 n] (`work`; its stages before it). On the
    floor (`ground`) the rotor states' only: each entry's arithmetic is the whole step's (a rotor's
    rate depends on its own state and command), and the rigid body's entries are left as they are."""
    n = x.shape[0]
    lo = N_RIGID if ground else 0
    y = 4 * n
    hh = 0.5 * h
    stage(x, 0, cmd, codes, q, wk, 0, ground)
    for i in range(lo, n):
        wk[y + i] = x[i] + hh * wk[i]
    stage(wk, y, cmd, codes, q, wk, n, ground)
    for i in range(lo, n):
        wk[y + i] = x[i] + hh * wk[n + i]
    stage(wk, y, cmd, codes, q, wk, 2 * n, ground)
    for i in range(lo, n):
        wk[y + i] = x[i] + h * wk[2 * n + i]
    stage(wk, y, cmd, codes, q, wk, 3 * n, ground)
    h6 = h / 6.0
    for i in range(lo, n):
        wk[y + i] = x[i] + h6 * (wk[i] + 2.0 * (wk[n + i] + wk[2 * n + i]) + wk[3 * n + i])


def period(x, P1, P2, P3, P4, codes, q, h, ground, out):
    """The plant's step (`Plant.advance`) in one call: the commanded thrusts (eq. 26) and speeds
    (eq. 27) of the command values P1..P4, one `rk4` step of h on x in place (on the floor, `ground`,
    the extensions' states only), then the forces at the new state into out (`N_OUT`)."""
    n = x.shape[0]
    wk = work(n)
    cmd = commanded(P1, P2, P3, P4, q)
    rk4(x, cmd, codes, q, h, wk, ground)
    for i in range(N_RIGID if ground else 0, n):
        x[i] = wk[4 * n + i]
    f, tau, F, T, w = forces(x, cmd, codes, q, wk)
    for i in range(4):
        out[i], out[4 + i], out[14 + i] = f[i], tau[i], w[i]
    for i in range(3):
        out[8 + i], out[11 + i] = F[i], T[i]


def forces_of(x, P1, P2, P3, P4, codes, q):
    """`forces` with its own scratch: (f, tau, F, T, w), f, tau and w arrays (the single plant's)."""
    f, tau, F, T, w = forces(x, commanded(P1, P2, P3, P4, q), codes, q, work(x.shape[0]))
    return np.array(f), np.array(tau), F, T, np.array(w)


@functools.cache
def model_period():
    """`period` compiled, with every function it calls (eq. 6-9 and 26-28 and the three effects'), or None."""
    return functions().get("period")


@functools.cache
def model_forces():
    """`forces_of` compiled, or None."""
    return functions().get("forces_of")


@functools.cache
def functions() -> dict:
    """The plant's functions compiled, each call bound to a compiled copy: `rk4`, `forces`, `period`,
    `commanded` (and the batched simulator's `rotation_from_trig`, `attitude_trig`); empty when compilation is off."""
    if not enabled():
        return {}
    from flightctl import physics
    from flightctl.sim.world import model
    from flightctl.sim.causes import motor_dynamics, rotor_drag, rotor_inflow
    c = compiled_copy
    eq = {name: c(getattr(physics, name)) for name in ("yaw_drag", "rotor_torque", "rotor_speed", "thrust_from_speed")}
    m = {name: c(getattr(model, name)) for name in ("rotation_from_trig", "body_velocity", "aggregate", "body_torques",
                                                    "angular_acceleration", "euler_rates")}
    rigid = c(model.rigid_derivative, yaw_drag=eq["yaw_drag"], angular_acceleration=m["angular_acceleration"],
              euler_rates=m["euler_rates"])
    inflow = c(rotor_inflow.inflow_wrench, body_torques=m["body_torques"], thrust_change=c(rotor_inflow.thrust_change))
    flow = c(rotor_inflow.airflow, airflow_share=c(rotor_inflow.airflow_share))
    rates = c(rotor_rates, speed_rate=c(motor_dynamics.speed_rate))
    trig = c(attitude_trig)
    wrenches = c(rotors, inflow_wrench=inflow, drag_wrench=c(rotor_drag.drag_wrench), airflow=flow,
                 rotor_rates=rates, reaction_torque=c(motor_dynamics.reaction_torque),
                 rotor_torque=eq["rotor_torque"], thrust_from_speed=eq["thrust_from_speed"],
                 body_velocity=m["body_velocity"])
    one = c(stage, rotors=wrenches, rigid_derivative=rigid, rotation_from_trig=m["rotation_from_trig"],
            attitude_trig=trig, rotor_rates=rates, aggregate=m["aggregate"])
    step = c(rk4, stage=one)
    command = c(commanded, thrust_from_command=c(physics.thrust_from_command), rotor_speed=eq["rotor_speed"],
                esc_command=c(physics.esc_command))
    at = c(forces, rotors=wrenches, rotation_from_trig=m["rotation_from_trig"], attitude_trig=trig)
    scratch = c(work, allocates=True)
    once = c(period, allocates=True, rk4=step, forces=at, commanded=command, work=scratch)
    alone = c(forces_of, allocates=True, forces=at, work=scratch, commanded=command)
    # compiled (or loaded from the cache) now, with the flight's argument types, not at a first step
    # that a simulation paced by the wall clock (`run --board sim`, `hil serve`) would see as a stall
    x, codes, q = np.zeros(N_RIGID + 4), np.array([INFLOW, REACTION, DRAG], dtype=np.int64), np.ones(_RIGID + 8)
    once(x, 0.0, 0.0, 0.0, 0.0, codes, q, 1e-3, False, np.empty(N_OUT))
    alone(x, 0.0, 0.0, 0.0, 0.0, codes, q)
    return {"rk4": step, "forces": at, "forces_of": alone, "period": once, "commanded": command, "work": scratch,
            "rotation_from_trig": m["rotation_from_trig"], "attitude_trig": trig}
