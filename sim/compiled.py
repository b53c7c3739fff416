"""The simulator's hot functions compiled by numba where it is installed (the `fast` extra), from
their one plain-Python source: `compile(fn, name=dependency, ...)` compiles a copy of `fn` whose
global names of other plain functions are bound to their compiled copies, so that the plain
function stays plain (arrays in the batched simulator, and everywhere without numba). Nothing on
the vehicle imports this: the onboard code is plain Python.

`FLIGHTCTL_JIT=0` in the environment turns compilation off (a comparison, or a machine where numba
misbehaves); `ENABLED` says whether it is on. Compiled code is cached beside the source (numba's
`cache=True`): the first flight of a fresh install compiles for a few seconds, later ones load it.
"""
from __future__ import annotations

import functools
import os
import types


@functools.cache
def enabled() -> bool:
    """numba is installed and not turned off."""
    if os.environ.get("FLIGHTCTL_JIT", "1") == "0":
        return False
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def compile(fn, **dependencies):
    """`fn` compiled in nopython mode, its globals named in `dependencies` replaced (the compiled
    copies of the plain functions it calls); None when compilation is off."""
    if not enabled():
        return None
    import numba
    g = dict(fn.__globals__)
    g.update(dependencies)
    copy = types.FunctionType(fn.__code__, g, fn.__name__, fn.__defaults__, fn.__closure__)
    copy.__qualname__, copy.__module__, copy.__doc__ = fn.__qualname__, fn.__module__, fn.__doc__
    return numba.njit(cache=True, nogil=True)(copy)


@functools.cache
def rk4_rigid():
    """`flightctl.sim.model.rk4_rigid` compiled (with `rigid_derivative`, eq. 7's
    `angular_acceleration` and eq. 6's `yaw_drag`), or None."""
    if not enabled():
        return None
    from flightctl import physics
    from flightctl.sim import model
    yaw_drag = compile(physics.yaw_drag)
    angular = compile(model.angular_acceleration)
    rigid = compile(model.rigid_derivative, yaw_drag=yaw_drag, angular_acceleration=angular)
    stage = compile(model._rigid_array, rigid_derivative=rigid)
    return compile(model.rk4_rigid, _rigid_array=stage)

