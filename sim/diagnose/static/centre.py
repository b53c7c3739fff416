"""One centre of mass per flight (docs/diagnose.md, "Centre of mass").

A flight's log can give its centre of mass four ways, and the report names one (`one`), keeping the
others as checks beside it:

- **the rotor speeds** (`from_speeds`), where the log measured them (ESC telemetry, eRPM; omega1..N):
  in hover the rotors' thrusts hold zero roll and pitch torque about the centre of mass (eq. 25's roll
  and pitch rows), sum_i T_i (r_i - d) = 0, and each rotor's thrust is c1 Omega_i^2 (eq. 27, one
  propeller for all), so d = sum_i Omega_i^2 r_i / sum_i Omega_i^2 (positions from the thrust centre).
  No thrust curve and no motor's strength enter: a weak motor turns slower for its command, not for
  its thrust. The hover blocks' means of Omega_i^2 (`blocks.Blocks`: a ratio of means, block-jackknife
  standard errors). Chosen first: it is measured, not inferred.
- **the base model's** (`base_model.com`, the dynamic tier): the torques the flight's motion shows, each
  rotor's gain apart, through the fitted curve (eq. 26's h2). Chosen without rotor speeds, unless its h2
  sits at the end of its search (`base_model.h2.at_bound`): then the flight did not show the curve's
  shape, the torques' lever arms are the search's, and the figure is a check only, flagged.
- **the dynamic tier's hover gains** (`rotor_gain_check.com`): the base model's thrusts in hover
  (`base_model.hover_gain`, each rotor's gain and the centre of mass's trim together), with each rotor's
  own thrust per command from its speed (eq. 27) taken out where the log has speeds, read as the trim of
  a centre of mass (`rotorspeed.com_of_gains`: the part of the pattern linear in the rotors' positions),
  its standard errors the hover gains' carried through to first order. The same flight's torques as the
  base model's, balanced in hover rather than fitted with the gains apart: a check only, never the one
  named, flagged as the base model's is.
- **the static tier's commands** (`static.pattern.com`): the hover shares of the commanded thrust through
  the curve (`curve`); a rotor's own thrust per command (a weak or strong motor, its ESC) is in them too,
  so they are chosen last, said so.

Each check carries its difference from the one named, in its combined standard errors
(`AGREE_SIGMA`) or within `AGREE_ABS` arm lengths (the rotors' own spread of thrust per command, a few
% of thrust, moves a commands' figure by about that much).
"""
from __future__ import annotations

import numpy as np

from flightctl.sim.diagnose.data import FileData, Layout
from flightctl.sim.diagnose.static.blocks import Blocks

AGREE_SIGMA = 3.0      # a check agrees within this many combined standard errors ...
AGREE_ABS = 0.005      # ... or within this (arm lengths, or m on a layout in m)

SPEEDS = "the rotor speeds"
BASE = "the base model"
GAINS = "the dynamic tier's hover gains"
COMMANDS = "the static tier's commands"
WHY = {SPEEDS: "each rotor's thrust in hover measured by its speed, c1 Omega^2 (eq. 27): free of the thrust curve "
               "and of any motor's thrust per command",
       BASE: "the flight's torques with each rotor's gain apart (no rotor speeds in the log)",
       COMMANDS: "the hover shares of the commanded thrust through the curve: a motor's own thrust per command is in "
                 "them too (no rotor speeds in the log, and no base model identified)"}


def _unit(layout: Layout) -> str:
    return "m" if layout.unit == "m" else "arm lengths"


def from_speeds(files: list[FileData], bl: Blocks, layout: Layout) -> dict | None:
    """{dx, dy, stderr, unit, thrust_share, what} of the centre of mass from the rotor speeds on the
    hover rows of `bl` (the module's docstring), or None when a hover file has no rotor speeds or too
    few hover blocks have all speeds finite."""
    if not bl.enough:
        return None
    sq = []
    for f, m in zip(files, bl.masks):
        if not m.any():
            continue
        if f.omega is None:
            return None
        w = f.omega[:, m].astype(float)
        ok = np.isfinite(w).all(axis=0)          # rows without the N speeds: left out of their block's mean
        sq.append(np.where(ok, w * w, np.nan))
    w2 = np.concatenate(sq, axis=1)
    means = bl.means(w2)                         # (blocks, N) mean Omega_i^2, the NaN rows left out
    if not np.isfinite(means).all() or (means <= 0).any():
        return None
    R = np.column_stack([layout.x, layout.y])
    R = R - R.mean(axis=0)                       # from the thrust centre

    def stat(v):
        return np.concatenate([v @ R / v.sum(), v / v.mean()])

    full, sd, _ = bl.jackknife(means, stat)
    n = R.shape[0]
    return {"dx": round(float(full[0]), 4), "dy": round(float(full[1]), 4),
            "stderr": [float(f"{e:.2g}") for e in sd[:2]], "unit": _unit(layout),
            "thrust_share": [round(float(v), 4) for v in full[2:2 + n]],
            "thrust_share_stderr": [float(f"{e:.2g}") for e in sd[2:2 + n]],
            "what": "the centre of mass off the thrust centre (x forward, y left) from the rotor speeds in hover: "
                    "d = sum_i Omega_i^2 r_i / sum_i Omega_i^2 (zero roll and pitch torque, thrust c1 Omega^2, eq. 25 "
                    "and 27) on the hover blocks' means of Omega_i^2, block-jackknife standard errors; thrust_share: "
                    "each rotor's Omega^2 against the rotors' mean"}


def _entry(source: str, com: dict, flag: str | None = None) -> dict:
    return {"source": source, "dx": com["dx"], "dy": com["dy"], "stderr": list(com["stderr"]), "unit": com["unit"],
            **({"flag": flag} if flag else {})}


def _commands_with_speeds(static: dict, speeds: dict) -> dict:
    """The commands' centre of mass with each rotor's own thrust per command (its speed's, eq. 27,
    `speed_thrust_gain`) taken into its share: what the commands' figure is once the rotors' differences
    are out of it (d = sum_i s_i q_i r_i / sum_i s_i q_i)."""
    L = static["layout"]
    R = np.column_stack([L["x"], L["y"]])
    R = R - R.mean(axis=0)
    t = np.asarray(static["motors"]["share"], float) * np.asarray(speeds["speed_thrust_gain"], float)
    d = t @ R / t.sum()
    return {"dx": round(float(d[0]), 4), "dy": round(float(d[1]), 4),
            "what": "the commands' hover shares times each rotor's thrust per command from its speed "
                    "(static.pattern.rotor_speeds.speed_thrust_gain): the commands' figure with the rotors' own "
                    "differences taken out"}


def one(base_model: dict | None, static: dict | None, gain_check: dict | None = None) -> dict | None:
    """The report's `centre_of_mass`: the one figure (source, why) and the others as checks, each with its
    difference from it (`agree`), or None when no tier gave one. `gain_check`: the dynamic tier's
    `rotor_gain_check` (its `com`, a check only)."""
    cands = []
    speeds = ((static or {}).get("pattern") or {}).get("rotor_speeds") or {}
    if speeds.get("com"):
        cands.append(_entry(SPEEDS, speeds["com"]))
    if base_model and base_model.get("identified") and base_model.get("com"):
        h2 = base_model.get("h2", {})
        flag = (f"h2 = {h2['value']:g} sits at the end of its search (base_model.h2.at_bound): the flight did not show "
                "the thrust curve's shape, so the torques' lever arms are the search's: a check only"
                if h2.get("at_bound") else None)
        cands.append(_entry(BASE, base_model["com"], flag))
        if gain_check and (g := gain_check.get("com")) and g.get("stderr"):
            cands.append({**_entry(GAINS, g, flag), "check_only": True})
    pattern = (static or {}).get("pattern") or {}
    if pattern.get("com"):
        flag = None if (static or {}).get("thrust_curve", "").startswith("eq. 26 with") else \
            "through an assumed thrust curve (h2 = 0): its size scales with the curve's slope"
        cands.append(_entry(COMMANDS, pattern["com"], flag))
    if not cands:
        return None
    named = [c for c in cands if not c.pop("check_only", False)]
    chosen = next((c for c in named if "flag" not in c), named[0])
    checks = []
    for c in cands:
        if c is chosen:
            continue
        diff = np.array([c["dx"] - chosen["dx"], c["dy"] - chosen["dy"]])
        sig = np.hypot(np.array(c["stderr"], float), np.array(chosen["stderr"], float))
        z = np.abs(diff) / np.maximum(sig, 1e-12)
        agree = bool(((z <= AGREE_SIGMA) | (np.abs(diff) <= AGREE_ABS)).all())
        check = {**c, "difference": [round(float(v), 4) for v in diff],
                 "sigmas": [round(float(v), 1) for v in z], "agree": agree}
        if c["source"] == COMMANDS and speeds.get("speed_thrust_gain") and static.get("motors"):
            check["with_speeds"] = _commands_with_speeds(static, speeds)
        checks.append(check)
    why = WHY[chosen["source"]] + (f"; {chosen['flag']}" if "flag" in chosen else "")
    return {**{k: chosen[k] for k in ("source", "dx", "dy", "stderr", "unit")}, "why": why, "checks": checks,
            "what": "the one centre of mass of the flight off the thrust centre (x forward, y left): from the rotor "
                    "speeds where the log has them, else the base model's, else the static tier's commands "
                    "(sim/diagnose/static/centre.py); checks: the others (and the dynamic tier's hover gains', a check "
                    f"only), agreeing within {AGREE_SIGMA:g} combined "
                    f"standard errors or {AGREE_ABS:g} {chosen['unit']}"}


def centre_text(c: dict) -> str:
    """The report's line of `one`'s answer."""
    line = (f"  centre of mass (from {c['source']}): dx {c['dx']:+.4f} +- {c['stderr'][0]:.2g}, dy {c['dy']:+.4f} "
            f"+- {c['stderr'][1]:.2g} {c['unit']} from the thrust centre ({c['why']})")
    for k in c["checks"]:
        line += (f"\n    check, {k['source']}: ({k['dx']:+.4f} +- {k['stderr'][0]:.2g}, {k['dy']:+.4f} +- "
                 f"{k['stderr'][1]:.2g}): " + ("agrees" if k["agree"] else "disagrees") + f" ({k['sigmas'][0]:g}, "
                 f"{k['sigmas'][1]:g} standard errors)" + (f"; {k['flag']}" if "flag" in k else ""))
        if w := k.get("with_speeds"):
            line += (f"; with each rotor's thrust per command from its speed: ({w['dx']:+.4f}, {w['dy']:+.4f})")
    return line
