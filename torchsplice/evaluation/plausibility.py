"""The evaluation report's section on plausibility: how often a result puts a hand inside its
body, and how its feet, floor and jerk are distributed.

Read from the job's columns (``penetration`` and its sources' figures,
:func:`torchsplice.ops.plausibility.penetration`; ``foot_skate``, ``foot_slide``, ``floor``,
``jerk`` and the action's ``jerk_action``, :func:`torchsplice.ops.plausibility.clip_figures`),
per method, against the sources where the output has theirs: so that a method that makes the
problem (or the naive splice, which has it too) shows beside the others. Outputs written
before a column existed get no line of it (no section without any).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..formats.exporters import clip_filenames

__all__ = ["PLAUSIBILITY_COLUMNS", "FIGURE_COLUMNS", "FIGURES", "plausibility_rows", "figure_stats",
           "plausibility_section", "figures_section", "plausibility_pictures", "WORST", "PICTURED"]

PLAUSIBILITY_COLUMNS = ("penetration", "penetration_depth", "penetration_locomotion", "penetration_action")
"""The columns a clip's row takes from the output's table (when it has them all)."""
FIGURE_COLUMNS = ("foot_skate", "foot_slide", "floor", "jerk", "jerk_action")
"""The job's figures of a result's feet, floor and jerk, and its action's jerk, each taken by its
own name where the output's table has it (docs/job.md, "Feet, floor and jerk")."""
FIGURES = (  # (key, the table's heading, quantiles, format)
    ("foot_skate", "foot skate, GMD's ratio", (0.5, 0.95), "{:.3f}"),
    ("foot_slide", "foot slide (cm/s)", (0.5, 0.95), "{:.1f}"),
    ("floor", "floor (cm)", (0.05, 0.5, 0.95), "{:.1f}"),
    ("jerk", "jerk (m/s^3)", (0.5, 0.95), "{:.0f}"),
    ("jerk_action", "the actions' jerk (m/s^3)", (0.5, 0.95), "{:.0f}"),
    ("jerk_over_action", "jerk / the action's", (0.5, 0.95), "{:.2f}"),
)
"""The distributions :func:`figures_section` shows and :func:`figure_stats` gives, per method;
``jerk_over_action`` is each clip's ``jerk`` over its ``jerk_action``."""
WORST = 5
"""Clips the section names per method, those beyond their sources the most."""
PICTURED = 2
"""Of those, the clips drawn per method (:func:`plausibility_pictures`)."""
SPAN = 0.5
"""Seconds drawn each side of the frame where a hand goes deepest."""


def plausibility_rows(t, i: int) -> dict:
    """The plausibility figures of row ``i`` of the clip table ``t`` (empty when it has none): the
    hand-in-body columns where it has them all, and each of :data:`FIGURE_COLUMNS` it has."""
    out = {}
    if all(c in t for c in PLAUSIBILITY_COLUMNS):
        out = {c: float(t[c][i]) for c in PLAUSIBILITY_COLUMNS}
        if "corrected_frames" in t:  # outputs written before the correction have none
            out["corrected_frames"] = max(int(t["corrected_frames"][i]), 0)
    out.update({c: float(t[c][i]) for c in FIGURE_COLUMNS if c in t})  # outputs before the figures have none
    return out


def _quantile(values: list[float], q: float) -> float:
    """The ``q`` quantile of ``values`` (one of them), NaN for none."""
    return float(np.quantile(values, q, method="inverted_cdf")) if values else math.nan


def _depth(depths: list[float]) -> str:
    """The 95th percentile of the depths of the clips with a frame inside, "-" for none."""
    return f"{_quantile(depths, 0.95):.1f}" if depths else "-"


def _corrected(cs: list[dict]) -> str:
    """The clips and frames whose arms were moved out of the body, or "-" where not recorded."""
    if not all("corrected_frames" in c for c in cs):
        return "-"
    moved = [c["corrected_frames"] for c in cs]
    return f"{sum(m > 0 for m in moved)}, {sum(moved)}"


def _values(cs: list[dict], key: str) -> list[float]:
    """The finite values of ``key`` over the clips ``cs`` (``jerk_over_action``: each clip's jerk
    over its action's, where that is above 0)."""
    if key == "jerk_over_action":
        vals = [c["jerk"] / c["jerk_action"] for c in cs
                if "jerk" in c and c.get("jerk_action", math.nan) > 0 and math.isfinite(c["jerk_action"])]
    else:
        vals = [c[key] for c in cs if key in c]
    return [v for v in vals if math.isfinite(v)]


def _stat_name(key: str, q: float) -> str:
    return f"{key}_median" if q == 0.5 else f"{key}_p{round(100 * q)}"


def _shown(per_clip: list[dict]) -> list[tuple]:
    """The :data:`FIGURES` the clips have (by their columns: NaN values count, as "-")."""
    have = {k for c in per_clip for k in FIGURE_COLUMNS if k in c}
    need = {"jerk_over_action": ("jerk", "jerk_action")}
    return [f for f in FIGURES if all(k in have for k in need.get(f[0], (f[0],)))]


def figure_stats(cs: list[dict]) -> dict:
    """The distributions of :data:`FIGURES` over the clips ``cs`` that have them: for each its
    quantiles, ``"<key>_median"`` and ``"<key>_p95"`` (``floor`` also ``"floor_p5"``), each one
    clip's value (the smallest at or above that share of the clips), ``None`` where no clip has a
    finite value; no key for a figure no clip has."""
    out: dict = {}
    for key, _, qs, _ in _shown(cs):
        vals = _values(cs, key)
        out.update({_stat_name(key, q): _quantile(vals, q) if vals else None for q in qs})
    return out


def figures_section(per_clip: list[dict], methods: list[str], md) -> list[str]:
    """Markdown lines of the feet, floor and jerk (none when the clips have none of their columns)."""
    shown = _shown(per_clip)
    if not shown:
        return []

    def head(label, qs):
        return label + ", " + " / ".join("median" if q == 0.5 else f"{round(100 * q)}th pct." for q in qs)

    lines = ["## Plausibility: feet, floor and jerk", "",
             "| method | clips | " + " | ".join(head(label, qs) for _, label, qs, _ in shown) + " |",
             "|---|---|" + "---|" * len(shown)]
    for m in methods:
        cs = [c for c in per_clip if c["method"] == m]
        if not cs:
            continue
        st = figure_stats(cs)
        cells = [" / ".join("-" if st.get(_stat_name(key, q)) is None else fmt.format(st[_stat_name(key, q)])
                            for q in qs) for key, _, qs, fmt in shown]  # "-" too where this method's clips lack it
        lines.append(f"| {md(m)} | {len(cs)} | " + " | ".join(cells) + " |")
    keys = {f[0] for f in shown}
    text = []
    if keys & {"foot_skate", "foot_slide", "floor"}:
        text.append("Foot skate: GMD's skate ratio, the share of steps (at 20 fps) in which a foot within 5 cm of the "
                    "clip's lowest foot point moves faster than 0.5 m/s; foot slide: the mean horizontal speed of a "
                    "foot in contact; floor: the lowest a foot goes from the ground plane (below 0 it is under the "
                    "ground). The sources' foot figures are not in the output (the job records the actions' jerk, "
                    "not the locomotions' feet), so the feet are the results' alone.")
    if "jerk" in keys:
        text.append("Jerk: the largest third difference of the elbows, wrists and head in the chest's frame, the mean "
                    "over them" + (", beside the action's own (the job's jerk_action) and the one over the other per "
                    "clip: a loop seam or a timewarp kink shows as a result's jerk far above its action's."
                    if "jerk_action" in keys else "."))
    text.append("Each median and percentile is one clip's value (the smallest at or above that share of the clips); "
                "\"-\": no finite value (as where the skeleton's units are unknown).")
    return lines + ["", " ".join(text), ""]


def plausibility_section(per_clip: list[dict], methods: list[str], md) -> list[str]:
    """Markdown lines of the section (none when the clips have no figures); ``md`` escapes text."""
    if not per_clip or "penetration" not in per_clip[0]:
        return figures_section(per_clip, methods, md)
    lines = ["## Plausibility: a hand inside the body", "",
             "| method | clips | a frame inside | beyond both sources by 0.05 (flagged) | frames inside, mean / 95th pct. | "
             "depth at worst, 95th pct. (cm) | the locomotions' frames inside, mean | the actions', mean | "
             "arms moved out of the body: clips, frames |",
             "|---|---|---|---|---|---|---|---|---|"]
    worst_lines: list[str] = []
    for m in methods:
        cs = [c for c in per_clip if c["method"] == m]
        if not cs:
            continue
        shares = [c["penetration"] for c in cs]
        beyond = [c["penetration"] - max(c["penetration_locomotion"], c["penetration_action"]) for c in cs]
        inside = [c for c in cs if c["penetration"] > 0]
        lines.append(f"| {md(m)} | {len(cs)} | {100 * len(inside) / len(cs):.1f}% | "
                     f"{100 * sum(b > 0.05 for b in beyond) / len(cs):.1f}% | {100 * sum(shares) / len(cs):.2f}% / "
                     f"{100 * _quantile(shares, 0.95):.1f}% | {_depth([c['penetration_depth'] for c in inside])} | "
                     f"{100 * sum(c['penetration_locomotion'] for c in cs) / len(cs):.2f}% | "
                     f"{100 * sum(c['penetration_action'] for c in cs) / len(cs):.2f}% | {_corrected(cs)} |")
        ranked = sorted(zip(beyond, cs), key=lambda x: -x[0])[:WORST]
        named = [f"{md(c['name'])} ({100 * c['penetration']:.0f}% of frames, {c['penetration_depth']:.1f} cm; sources "
                 f"{100 * c['penetration_locomotion']:.0f}% / {100 * c['penetration_action']:.0f}%)"
                 for b, c in ranked if b > 0]
        if named:
            worst_lines.append(f"- {md(m)}: " + "; ".join(named))
    lines += ["", "A frame counts when a forearm's axis (the hand included) lies more than 0.02 of the character's "
              "height (3 cm on SMPL-22) inside the torso, pelvis, head, a thigh or a shin of the skeleton's body of "
              "capsules; depth is measured from the capsule's surface. The sources' figures are the locomotion's "
              "and the action's own (the action as spliced): a result is judged against what its sources already "
              "do. Lower is better. Unless the job ran with --no-keep-hands-out, an arm whose forearm went "
              "deeper than its sources' was moved out by IK (torchsplice.ops.hands), and the figures are those "
              "of the corrected result.", ""]
    if worst_lines:
        lines += ["Most beyond their sources:", "", *worst_lines, ""]
    return lines + figures_section(per_clip, methods, md)


def _beyond(c: dict) -> float:
    return c["penetration"] - max(c["penetration_locomotion"], c["penetration_action"])


def plausibility_pictures(db, per_clip: list[dict], methods: list[str], folder, relative_to) -> list[tuple[str, str]]:
    """Filmstrips of the results most beyond their sources (:data:`PICTURED` per method), each
    the second around the frame where a hand goes deepest, seen from a camera across the
    contact (looking along neither the hand's way out nor the body, so the gap or the overlap
    shows): ``(caption, path relative to relative_to)`` pairs; none where no clip is beyond."""
    # torch and the drawing are imported here: the rest of this module (the tables) needs only numpy
    import torch

    from ..ops.body import body_of, capsule_ends, inside_depth, segment_closest
    from ..viz.camera import canonical_axes
    from ..viz.render import render

    if not per_clip or "penetration" not in per_clip[0]:
        return []
    chosen = []
    for m in methods:
        ranked = sorted((c for c in per_clip if c["method"] == m and _beyond(c) > 0), key=lambda c: -_beyond(c))
        chosen += ranked[:PICTURED]
    out = []
    for c, stem in zip(chosen, clip_filenames([c["name"] for c in chosen], "")):
        clip = db.read(c["name"], dtype=torch.float64)
        k = int(db.clip_info(c["name"])["skeleton"])
        spec = db.spec(k)
        body = body_of(clip.skeleton, spec.bind(clip.skeleton), c["name"])
        pos = clip.global_positions()
        depth = inside_depth(pos, body)  # (T, P, O)
        t = int(depth.flatten(1).amax(1).argmax())
        p, o = divmod(int(depth[t].argmax()), len(body.obstacles))
        a, b = capsule_ends(pos[t], body)
        pi, oi = body.probes[p], body.obstacles[o]
        s, u = segment_closest(a[pi], b[pi], a[oi], b[oi])
        normal = (a[pi] + s * (b[pi] - a[pi])) - (a[oi] + u * (b[oi] - a[oi]))
        up = "xyz".index(spec.up_axis)
        e1, e2, _ = (float(normal[i]) for i in canonical_axes(up))
        azimuth = math.degrees(math.atan2(e2, e1)) + 90.0  # the way out runs across the picture
        half = max(1, int(round(SPAN * clip.fps)))
        even = min(half, t, clip.num_frames - 1 - t)  # the deepest frame in the middle picture where it can be
        half = even if even >= 2 else half
        lo, hi = max(0, t - half), min(clip.num_frames, t + half + 1)
        png = Path(folder) / f"{stem}_inside.png"
        deepest = float(depth[t, p, o]) * _cm(spec.units)
        where = "the middle picture" if t - lo == hi - 1 - t else f"picture frame {t - lo}"
        title = (f"{c['name']}: {body.names[pi]} in {body.names[oi]}, clip frames {lo}-{hi - 1}, deepest at {t} "
                 f"({where}, {deepest:.1f} cm)")
        render([clip.slice(lo, hi)], png, titles=[title], frames=5, up_axis=up, camera="world", azimuth=azimuth,
               elevation=10.0)
        out.append((f"{c['method']}: {title}", str(png.relative_to(relative_to))))
    return out


def _cm(units: str) -> float:
    from ..ops.units import centimetres  # here, as above: loads torch

    return centimetres(units)
