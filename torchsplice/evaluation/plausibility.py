"""The evaluation report's section on plausibility: how often a result puts a hand inside its body.

Read from the job's columns (``penetration`` and its sources' figures,
:func:`torchsplice.ops.plausibility.penetration`), per method, against the sources: so that a
method that makes the problem (or the naive splice, which has it too) shows beside the others.
Outputs written before the columns existed get no section.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["PLAUSIBILITY_COLUMNS", "plausibility_rows", "plausibility_section", "plausibility_pictures", "WORST",
           "PICTURED"]

PLAUSIBILITY_COLUMNS = ("penetration", "penetration_depth", "penetration_locomotion", "penetration_action")
"""The columns a clip's row takes from the output's table (when it has them)."""
WORST = 5
"""Clips the section names per method, those beyond their sources the most."""
PICTURED = 2
"""Of those, the clips drawn per method (:func:`plausibility_pictures`)."""
SPAN = 0.5
"""Seconds drawn each side of the frame where a hand goes deepest."""


def plausibility_rows(t, i: int) -> dict:
    """The plausibility figures of row ``i`` of the clip table ``t`` (empty when it has none)."""
    if not all(c in t for c in PLAUSIBILITY_COLUMNS):
        return {}
    out = {c: float(t[c][i]) for c in PLAUSIBILITY_COLUMNS}
    if "corrected_frames" in t:  # outputs written before the correction have none
        out["corrected_frames"] = max(int(t["corrected_frames"][i]), 0)
    return out


def _quantile(values: list[float], q: float) -> float:
    """The ``q`` quantile of ``values`` (one of them), NaN for none."""
    return float(np.quantile(values, q, method="inverted_cdf")) if values else math.nan


def _corrected(cs: list[dict]) -> str:
    """The clips and frames whose arms were moved out of the body, or "-" where not recorded."""
    if not all("corrected_frames" in c for c in cs):
        return "-"
    moved = [c["corrected_frames"] for c in cs]
    return f"{sum(m > 0 for m in moved)}, {sum(moved)}"


def plausibility_section(per_clip: list[dict], methods: list[str], md) -> list[str]:
    """Markdown lines of the section (none when the clips have no figures); ``md`` escapes text."""
    if not per_clip or "penetration" not in per_clip[0]:
        return []
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
                     f"{100 * _quantile(shares, 0.95):.1f}% | {_quantile([c['penetration_depth'] for c in inside], 0.95):.1f} | "
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
    return lines


def _beyond(c: dict) -> float:
    return c["penetration"] - max(c["penetration_locomotion"], c["penetration_action"])


def plausibility_pictures(db, per_clip: list[dict], methods: list[str], folder, relative_to) -> list[tuple[str, str]]:
    """Filmstrips of the results most beyond their sources (:data:`PICTURED` per method), each
    the second around the frame where a hand goes deepest, seen from a camera across the
    contact (looking along neither the hand's way out nor the body, so the gap or the overlap
    shows): ``(caption, path relative to relative_to)`` pairs; none where no clip is beyond."""
    from pathlib import Path

    import torch

    from ..formats.exporters import clip_filenames
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
    from ..ops.units import centimetres

    return centimetres(units)
