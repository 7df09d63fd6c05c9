"""``torchsplice evaluate``: judge a database written by the splice job, per clip and per method.

For every spliced clip (and, in aggregate, every method) the report gives:

- **foot speed in contact** (``foot_speed_in_contact``; not the job's ``foot_skate``, GMD's
  ratio): horizontal foot speed while the foot is in ground contact (file units/s);
- **arm-leg phase**: the lag between each arm's swing and the opposite leg's swing, as a
  fraction of the gait cycle, and whether it lies in the range seen in the captured source clips;
- **posture kept**: distance between the result's and the action's mean shoulder offset from
  the pelvis in the heading frame (small: the action's posture, e.g. a lean, survived);
- **ground-truth error**: mean upper-body joint error against the real capture of the same
  combination, where the spec declares ground truth (``[clips.ground_truth]``), overall and
  per locomotion type (the locomotion's ``content`` label: turn, side walk, run ...) with its
  mean, median and worst;
- for **standing actions** (see :mod:`torchsplice.evaluation.standing`): the action kept (the
  acting wrists' range of motion against the whole action's and against its best window of
  the result's length, with the worst pairs named), the wrist error, the idle arms' phase,
  the smoothness of the loop seams, and filmstrips of two such pairs;
- **plausibility** (see :mod:`torchsplice.evaluation.plausibility`): a hand inside the body, and
  the distributions of the job's ``foot_skate``, ``foot_slide``, ``floor`` and ``jerk`` columns
  (against the actions' ``jerk_action``), per method, where the output has them.

The source clips come from the databases recorded in the output's ``run`` attribute, from
``sources`` given explicitly, or from the output itself when the job copied them in.
"""

from __future__ import annotations

import csv as csv_module
import html
import io
import json as json_module
import math
import re
from pathlib import Path

import torch

from ..core.errors import TorchspliceError
from ..core.motion import Motion
from ..core.names import printable, spreadsheet_cell
from ..store.atomic import atomic_path
from ..store.database import MotionDatabase
from ..store.select import select_clips
from ..formats.exporters import clip_filenames
from ..retarget import RetargetTarget
from ..retarget.clips import Retargeter, needs_retargeting, source_label
from ..specs import DatasetSpec
from ..splice.clips import clips_to_tensors, resample_motion
from ..splice.registry import available_methods
from .defaults import DEFAULT_MAX_ROWS, DEFAULT_PICTURES
from .ground_truth import best_posture_error, upper_body_error
from .metrics import arm_leg_phase, arm_leg_phase_stats, foot_skate, posture_kept
from .plausibility import figure_stats, plausibility_pictures, plausibility_rows, plausibility_section
from .retargeting import wrist_spread
from .standing import standing_measures
from ..viz.alignment import plot_alignment
from ..viz.render import render
from ..viz.sources import SourceClips as _Sources, clip_spec, source_databases as _source_dbs

__all__ = ["evaluate_database", "locomotion_type", "error_stats", "ground_truth_by_type"]


def locomotion_type(loco: Motion) -> str:
    """The locomotion's type for the per-type breakdown: its ``content`` label (Bandai Namco:
    ``walk-turn-left``, ``walk-back``, ``run`` ...), else ``"-"``."""
    return str((loco.labels or {}).get("content") or "-")


def error_stats(errors) -> dict:
    """``{"n", "mean", "median", "worst"}`` of a list of errors (``None`` entries skipped; the
    statistics are ``None`` when none is left). The median of an even count is the mean of the
    two middle values."""
    vals = sorted(float(v) for v in errors if v is not None and math.isfinite(v))
    if not vals:
        return {"n": 0, "mean": None, "median": None, "worst": None}
    n = len(vals)
    median = vals[n // 2] if n % 2 else 0.5 * (vals[n // 2 - 1] + vals[n // 2])
    return {"n": n, "mean": sum(vals) / n, "median": median, "worst": vals[-1]}


def ground_truth_by_type(per_clip: list[dict], methods: list[str], key: str = "gt_error") -> dict:
    """Per method, per locomotion type (and ``"all"``): :func:`error_stats` of ``key`` (the
    ground-truth error, or ``"gt_bound"``: its best-constant-posture bound) over ``per_clip``
    rows (keys ``method``, ``loco_type`` and ``key``)."""
    out: dict = {}
    for m in methods:
        rows = [c for c in per_clip if c["method"] == m and c.get(key) is not None]
        if not rows:
            continue
        out[m] = {"all": error_stats([c[key] for c in rows])}
        for kind in sorted({c["loco_type"] for c in rows}):
            out[m][kind] = error_stats([c[key] for c in rows if c["loco_type"] == kind])
    return out


def _ground_truth_section(per_clip: list[dict], methods: list[str], units: str) -> list[str]:
    """The report's tables of ground-truth errors per locomotion type, and of their
    best-constant-posture bound (empty without ground truth)."""
    table = ground_truth_by_type(per_clip, methods)
    if not table:
        return []
    bound = ground_truth_by_type(per_clip, methods, "gt_bound")
    shown = [m for m in methods if m in table]
    kinds = sorted({k for m in shown for k in table[m] if k != "all"}) + ["all"]

    def rows(tab):
        out = ["| locomotion | triples | " + " | ".join(map(md, shown)) + " |", "|---|---|" + "---|" * len(shown)]
        for kind in kinds:
            n = max(tab.get(m, {}).get(kind, {"n": 0})["n"] for m in shown)
            cells = []
            for m in shown:
                st = tab.get(m, {}).get(kind)
                cells.append("-" if st is None or not st["n"] else
                             f"{_fmt(st['mean'])} / {_fmt(st['median'])} / {_fmt(st['worst'])}")
            out.append(f"| {'**all**' if kind == 'all' else md(kind)} | {n} | " + " | ".join(cells) + " |")
        return out

    return (["## Ground truth per locomotion type", "",
             f"Upper-body joint error against the capture ({units}): mean / median / worst over the triples.", ""]
            + rows(table)
            + ["", "The same after the best constant posture change per triple (one rotation of the upper body "
               "about the pelvis, chosen with the capture's help: an oracle). No method that keeps the action's "
               "motion and changes its posture by a constant rotation can go below it.", ""]
            + rows(bound) + [""])


def _find_capture(spec: DatasetSpec, loco: Motion, act: Motion, candidates) -> str | None:
    want = spec.ground_truth_labels(loco.labels, act.labels)
    if want is None:
        return None
    hits = sorted(n for n, role, lab in candidates if role != "spliced" and all(lab.get(k) == v for k, v in want.items()))
    hits = [h for h in hits if h not in (loco.name, act.name)]
    return hits[0] if hits else None


def _metrics(results: list[Motion], locos: list[Motion], acts: list[Motion], roles, fps: float) -> dict:
    sk = results[0].skeleton
    R = clips_to_tensors(results, sk)
    A = clips_to_tensors([resample_motion(a, fps) for a in acts], sk)
    return {
        "foot_speed_in_contact": foot_skate(R, roles, fps),
        "phase": arm_leg_phase(R, roles, fps),
        "posture": posture_kept(R, A, roles),
    }


_MARKDOWN = re.compile(r"([\\`*\[\]|~]|(?<![0-9A-Za-z])_|_(?![0-9A-Za-z]))")  # "a_b" is never emphasis; no [, no link
_MARKDOWN_START = re.compile(r"^(\s*(?:\d+)?)([-+#=.)])")


def md(text) -> str:
    """``text`` (a clip, method or spec name, a label) safe inside a Markdown report, as plain
    text: control characters escaped, Markdown's punctuation backslash-escaped (no emphasis,
    link, image, code span, table cell or HTML tag can start, nor a list or heading at the
    start), then ``&``, ``<`` and ``>`` as HTML entities (no tag or comment can start)."""
    text = _MARKDOWN.sub(r"\\\1", printable(str(text)))
    text = _MARKDOWN_START.sub(lambda m: m.group(1) + "\\" + m.group(2), text)
    return html.escape(text, quote=False)


def _fmt(v, digits=2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{digits}f}"


def evaluate_database(path, output, sources=None, pictures: bool = DEFAULT_PICTURES, max_rows: int = DEFAULT_MAX_ROWS,
                      examples: int = 3, csv=None, json=None, progress=None, select=None) -> dict:
    """Write the Markdown report for the splice job's output ``path`` to ``output``.

    Returns the aggregate figures per method (also in the report). Pictures (filmstrips and
    alignment plots of a few example pairs) go to ``<output stem>_files/`` beside the report.
    ``csv`` and ``json`` (paths, or ``None``) get every clip's row, the tables' ``max_rows`` cut
    aside (JSON: ``{"database", "units", "aggregates", "clips"}``, NaN as ``null``); each is
    written atomically. ``progress(iterable, total, description)`` wraps the batches measured.
    ``select``: selectors of the selection language (:mod:`torchsplice.store.select`) the
    evaluated clips must pass, e.g. ``"method:splice"`` or ``["flags:", "action:wave"]``.
    """
    path, output = Path(path), Path(output)
    with MotionDatabase.open(path) as db:
        if "method" not in db.columns or "locomotion" not in db.columns:
            raise TorchspliceError(f"{path}: not written by the splice job (no locomotion/method columns)")
        t = db.table()
        rows = [i for i, r in enumerate(t["role"]) if r == "spliced"]
        if not rows:
            raise TorchspliceError(f"{path}: holds no spliced clip")
        if select is not None:
            chosen = set(select_clips(db.clip_table(), select, "{select}", str(path)))
            rows = [i for i in rows if i in chosen]
            if not rows:
                raise TorchspliceError(f"{path}: {{select}} selects no spliced clip", options=("select",))
        srcs = _source_dbs(db, sources)
        try:
            return _evaluate(db, t, rows, _Sources(srcs, db), path, output, pictures, max_rows, examples,
                             (csv, json), progress)
        finally:
            for s in srcs:
                s.close()


def _method_order(names) -> list[str]:
    """The methods of a database in the registry's order (built-ins first), then any method
    not registered in this process (its plug-in was not loaded) by name."""
    known = available_methods()
    return sorted(names, key=lambda m: (known.index(m), "") if m in known else (len(known), m))


def _evaluate(db, t, rows, sources: _Sources, path, output, pictures, max_rows, examples, tables=(None, None),
              progress=None) -> dict:
    k = int(t["skeleton"][rows[0]])
    sk = db.skeletons[k]
    spec = db.spec(k)
    roles = spec.bind(sk)
    units = spec.units if spec.units != "unknown" else "units"
    units_k = db.skeleton_info(k).units or ""  # as stored, for the retargeting rule
    candidates = sources.captures()
    methods = _method_order({str(t["method"][i]) for i in rows})
    per_clip: list[dict] = []
    captured_names = set()
    moved: dict = {}  # action name -> the action retargeted onto the results' skeleton
    batches = [(method, chunk) for method in methods
               for mrows in ([i for i in rows if t["method"][i] == method],) for chunk in
               (mrows[b:b + 64] for b in range(0, len(mrows), 64))]
    for method, chunk in (progress(batches, len(batches), "evaluating") if progress else batches):
        results = [db.read(i) for i in chunk]
        locos = [sources.get(str(t["locomotion"][i])) for i in chunk]
        acts = [_action_as_spliced(sources, str(t["action"][i]), r, (path, k, spec, units_k), moved)
                for i, r in zip(chunk, results)]
        captured_names.update(m.name for m in locos + acts)
        fps = results[0].fps
        m = _metrics(results, locos, acts, roles, fps)
        caps = [_find_capture(spec, lo, ac, candidates) for lo, ac in zip(locos, acts)]
        gt, bound = [None] * len(chunk), [None] * len(chunk)
        have = [n for n, c in enumerate(caps) if c is not None]
        if have:
            got, want = [results[n] for n in have], [sources.get(caps[n]) for n in have]
            err, best = upper_body_error(got, want, roles), best_posture_error(got, want, roles)
            for n, e, o in zip(have, err.tolist(), best.tolist()):
                gt[n], bound[n] = e, o
        stand = _standing_rows(db, t, chunk, results, acts, roles)
        moves = _retarget_rows(db, chunk, results, locos, acts, roles, fps, moved)
        for n, i in enumerate(chunk):
            per_clip.append({
                "name": str(t["name"][i]), "method": method, "locomotion": str(t["locomotion"][i]),
                "action": str(t["action"][i]), "frames": int(t["length"][i]), "cost": float(t["cost"][i]),
                "foot_speed_in_contact": float(m["foot_speed_in_contact"][n]), "phase": float(m["phase"][n]),
                "posture": float(m["posture"][n]), "capture": caps[n], "gt_error": gt[n],
                "gt_bound": bound[n],
                "loco_type": locomotion_type(locos[n]),
                **stand.get(n, {"timing": "timewarp"}),
                **moves.get(n, {}),
                **plausibility_rows(t, i),
            })
    captured = [sources.get(n) for n in sorted(captured_names)]
    lo, hi = _captured_phase_band(captured, roles)
    for c in per_clip:
        c["phase_ok"] = lo <= c["phase"] <= hi
        c["abs_phase"] = abs(c["phase"])
    aggregates = _aggregate(per_clip, methods)
    figures = _pictures(db, sources, spec, per_clip, output, examples, moved) if pictures else []
    if pictures:  # the results with a hand furthest inside the body beyond their sources
        figures += plausibility_pictures(db, per_clip, methods, output.with_name(output.stem + "_files"), output.parent)
    text = _markdown(path, spec, units, methods, aggregates, per_clip, (lo, hi), figures, max_rows, len(captured))
    with atomic_path(output) as tmp:
        Path(tmp).write_text(text)
    _write_rows(tables, path, units, aggregates, per_clip)
    return aggregates


def _write_rows(tables, path, units, aggregates, per_clip) -> None:
    """Every clip's row as CSV and/or JSON (``tables``: their paths or ``None``), atomically."""
    def clean(v):
        return None if isinstance(v, float) and not math.isfinite(v) else v

    csv_path, json_path = tables
    if csv_path is not None:
        columns = list(dict.fromkeys(k for c in per_clip for k in c))
        out = io.StringIO()
        w = csv_module.DictWriter(out, columns, lineterminator="\n")
        w.writeheader()
        for c in per_clip:
            w.writerow({k: "" if clean(v) is None else spreadsheet_cell(v) for k, v in c.items()})
        with atomic_path(csv_path) as tmp:
            Path(tmp).write_text(out.getvalue())
    if json_path is not None:
        doc = {"database": str(path), "units": units,
               "aggregates": {m: {k: clean(v) for k, v in a.items()} for m, a in aggregates.items()},
               "clips": [{k: clean(v) for k, v in c.items()} for c in per_clip]}
        with atomic_path(json_path) as tmp:
            Path(tmp).write_text(json_module.dumps(doc, indent=1, allow_nan=False))


def _action_as_spliced(sources: _Sources, name: str, result: Motion, on: tuple, moved: dict) -> Motion:
    """The action clip ``name`` as the job spliced it into ``result``: retargeted onto the
    results' skeleton (``on``: the output's path, skeleton id, spec and units) when the job's
    rule says it was (:func:`~torchsplice.retarget.clips.needs_retargeting`), else as stored;
    made once per action (into ``moved``). Its feet rest at its own heights, scaled (the job used
    the locomotion database's): the upper body the report measures is the same."""
    if name in moved:
        return moved[name]

    path, k, spec, units = on
    act = sources.get(name)
    where = sources.where(name)
    ka = where.clip_info(name)["skeleton"]
    mine = where.skeleton_info(ka)
    if not needs_retargeting(act.skeleton, mine.units or "", result.skeleton, units, mine.up_axis or "", spec.up_axis):
        return act
    own = clip_spec(where, name)
    target = RetargetTarget(f"{Path(path).name}:{k}", result.skeleton, spec)
    moved[name] = Retargeter(act.skeleton, own, source_label(where.path, ka, own.name), target)([act])[0]
    return moved[name]


def _retarget_rows(db, chunk, results, locos, acts, roles, fps, moved: dict) -> dict[int, dict]:
    """Per position in ``chunk`` of a result whose action was retargeted: where from, the acting
    wrist's range of motion against the action's (as spliced, over the frames the result plays:
    :func:`~torchsplice.evaluation.retargeting.wrist_spread`) and the locomotion's foot speed in contact."""
    out = {}
    for n, (i, r, lo, ac) in enumerate(zip(chunk, results, locos, acts)):
        if ac.name not in moved or moved[ac.name] is not ac:  # spliced as stored
            continue
        side = max((0, 1), key=lambda s: wrist_spread(ac, roles, s))
        frames = ac.num_frames
        used = (db.read_frame_column(i, "action_frame").round().clip(0, frames - 1).astype(int)
                if "action_frame" in db.frame_columns else None)
        want = wrist_spread(ac, roles, side, used)
        out[n] = {"retargeted_from": ac.labels.get("retargeted_from", "?"),
                  "wrist_ratio": wrist_spread(r, roles, side) / want if want > 0 else float("nan"),
                  "locomotion_foot_speed_in_contact": float(foot_skate(clips_to_tensors([resample_motion(lo, fps)], lo.skeleton), roles, fps)[0])}
    return out


def _retarget_section(per_clip, methods, units) -> list[str]:
    moved = [c for c in per_clip if "retargeted_from" in c]
    if not moved:
        return []
    lines = ["## Retargeted pairs", "",
             f"{len(moved)} of {len(per_clip)} clips spliced an action retargeted onto the locomotion's skeleton "
             f"(from {', '.join(sorted({md(c['retargeted_from']) for c in moved}))}). Wrist range: the acting wrist's "
             "range of motion in the chest frame over arm length, against the action's as spliced over the frames "
             "the result plays (1 is the action's; the target is 0.8 to 1.2). Foot speed in contact against the locomotion's "
             f"({units}/s).", "",
             "| method | clips | wrist range, mean (min to max) | foot speed in contact minus the locomotion's, mean |", "|---|---|---|---|"]
    for m in methods:
        cs = [c for c in moved if c["method"] == m]
        if not cs:
            continue
        r = [c["wrist_ratio"] for c in cs]
        d = [c["foot_speed_in_contact"] - c["locomotion_foot_speed_in_contact"] for c in cs]
        lines.append(f"| {md(m)} | {len(cs)} | {sum(r) / len(r):.2f} ({min(r):.2f} to {max(r):.2f}) | "
                     f"{sum(d) / len(d):+.2f} |")
    return lines + [""]


def _standing_rows(db, t, chunk, results, acts, roles) -> dict[int, dict]:
    """Per position in ``chunk`` of a standing action's result: timing, acting arms and the
    measures of :mod:`torchsplice.evaluation.standing`."""
    if "timing" not in t:
        return {}
    idx = [n for n, i in enumerate(chunk) if str(t["timing"][i]) not in ("", "timewarp")]
    if not idx:
        return {}
    acting = [tuple(x for x in str(t["acting"][chunk[n]]).split(",") if x) for n in idx]
    curves = [torch.from_numpy(db.read_frame_column(chunk[n], "action_frame").astype("float64")) for n in idx]
    sm = standing_measures([results[n] for n in idx], [acts[n] for n in idx], curves, acting, roles)
    return {n: {"timing": str(t["timing"][chunk[n]]), "acting": ",".join(acting[k]),
                "range_kept": float(sm.range_kept[k]), "window_kept": float(sm.window_kept[k]),
                "wrist_error": float(sm.wrist_error[k]), "idle_lag": float(sm.idle_lag[k]),
                "seam_ratio": float(sm.seam_ratio[k])} for k, n in enumerate(idx)}


def _standing_section(per_clip: list[dict], methods: list[str], units: str, band: tuple[float, float]) -> list[str]:
    """The report's section on standing actions (empty when there are none)."""
    stand = [c for c in per_clip if c.get("timing", "timewarp") != "timewarp"]
    if not stand:
        return []
    lo, hi = band

    def stats(vals, worst=max):
        vals = [v for v in vals if v is not None and math.isfinite(v)]
        return (sum(vals) / len(vals), worst(vals)) if vals else (None, None)

    lines = ["## Standing actions", "",
             f"{len(stand)} clips put an action that does not locomote onto a locomotion "
             f"({', '.join(sorted({c['timing'] for c in stand}))}).", "",
             "| method | clips | action kept: range / the action's, mean | worst | range / its best window, mean | "
             f"worst | wrist error ({units}), mean | idle arms: lag within captured range | seam jump / capture's "
             f"99th pct., mean | worst | foot speed in contact ({units}/s), standing | the same, time-aligned |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for m in methods:
        cs = [c for c in stand if c["method"] == m]
        if not cs:
            continue
        whole, whole_min = stats([c["range_kept"] for c in cs], worst=min)
        window, window_min = stats([c["window_kept"] for c in cs], worst=min)
        err, _ = stats([c["wrist_error"] for c in cs])
        idle = [c["idle_lag"] for c in cs if math.isfinite(c["idle_lag"])]
        in_range = f"{100 * sum(lo <= x <= hi for x in idle) / len(idle):.0f}% of {len(idle)}" if idle else "-"
        seam, worst = stats([c["seam_ratio"] for c in cs])
        skate, _ = stats([c["foot_speed_in_contact"] for c in cs])
        other, _ = stats([c["foot_speed_in_contact"] for c in per_clip if c["method"] == m and c.get("timing", "timewarp") == "timewarp"])
        lines.append(f"| {m} | {len(cs)} | {_fmt(whole)} | {_fmt(whole_min)} | {_fmt(window)} | {_fmt(window_min)} | "
                     f"{_fmt(err)} | {in_range} | {_fmt(seam)} | {_fmt(worst)} | {_fmt(skate)} | {_fmt(other)} |")
    lines += ["", "Action kept: the acting wrists' range of motion in the chest's frame (the extent between their 5th and "
              "95th percentile positions), in the result over the same in the whole captured action, and over the "
              "largest such range of any window of the action as long as the result (about 1: the result plays the "
              "whole gesture, or its best part when the locomotion is shorter). Wrist error: mean distance of the "
              "acting wrists, in the chest's frame, from the action's at the same action frame (0: the frames played "
              "are the action's exactly). Idle arms: the arm-leg lag of the arms the action does not use, against the "
              "range of the captured walks. Seam jump: the largest change of the acting wrists' velocity around each "
              "loop point, over the 99th percentile of the same in the captured action (about 1 or less: as smooth as "
              "the capture). Foot speed in contact as above: the locomotion's, unchanged.", ""]
    worst_pairs = sorted((c for c in stand if math.isfinite(c["window_kept"])), key=lambda c: c["window_kept"])[:5]
    if worst_pairs:
        lines += ["Worst pairs (action kept against the best window):", ""]
        lines += [f"- {md(c['name'])} ({md(c['method'])}, {md(c['timing'])}): {_fmt(c['window_kept'])} of the best window, "
                  f"{_fmt(c['range_kept'])} of the whole action" for c in worst_pairs]
        lines.append("")
    return lines


def _captured_phase_band(captured: list[Motion], roles) -> tuple[float, float]:
    """Range of arm-leg lags over the captured clips whose arms clearly swing with the legs
    (correlation above 0.8 on both sides; a side-step or a held object says nothing)."""
    fps = captured[0].fps
    C = clips_to_tensors([resample_motion(c, fps) for c in captured], captured[0].skeleton)
    st = arm_leg_phase_stats(C, roles, fps)
    keep = torch.isfinite(st.lag) & (st.correlation.min(dim=1).values > 0.8)
    if not bool(keep.any()):
        return float("nan"), float("nan")
    lags = st.lag[keep]
    return float(lags.min()), float(lags.max())


def _aggregate(per_clip: list[dict], methods: list[str]) -> dict:
    out = {}
    for method in methods:
        cs = [c for c in per_clip if c["method"] == method]

        def mean(key):
            vals = [c[key] for c in cs if c[key] is not None and math.isfinite(c[key])]
            return sum(vals) / len(vals) if vals else None

        gt = [c["gt_error"] for c in cs if c["gt_error"] is not None]
        out[method] = {
            "clips": len(cs), "foot_speed_in_contact": mean("foot_speed_in_contact"), "phase": mean("abs_phase"),
            "phase_in_range": sum(c["phase_ok"] for c in cs) / len(cs), "posture": mean("posture"),
            "gt_error": sum(gt) / len(gt) if gt else None, "gt_pairs": len(gt), "cost": mean("cost"),
            "gt_by_type": ground_truth_by_type(cs, [method]).get(method, {}),
            "gt_bound": error_stats([c.get("gt_bound") for c in cs])["mean"],
            "gt_bound_by_type": ground_truth_by_type(cs, [method], "gt_bound").get(method, {}),
            **figure_stats(cs),
        }
    return out


def _pictures(db, sources, spec, per_clip, output: Path, examples: int, moved: dict | None = None) -> list[tuple[str, str]]:
    """A filmstrip (locomotion, action, each method) and an alignment plot for a few pairs."""
    folder = output.with_name(output.stem + "_files")
    folder.mkdir(exist_ok=True)
    first = [c for c in per_clip if c["method"] == per_clip[0]["method"]]
    chosen, seen = [], set()  # long pairs with a capture first, one per locomotion
    aligned = [c for c in first if c.get("timing", "timewarp") == "timewarp"]
    for c in sorted(aligned, key=lambda c: (c["capture"] is None, -c["frames"], c["name"])):
        if c["locomotion"] not in seen and len(chosen) < examples:
            chosen.append(c)
            seen.add(c["locomotion"])
    standing, acts = [], set()  # and two standing actions, of different actions
    for c in sorted((c for c in first if c.get("timing", "timewarp") != "timewarp"), key=lambda c: (-c["frames"], c["name"])):
        if c["action"] not in acts and len(standing) < 2:
            standing.append(c)
            acts.add(c["action"])
    chosen += standing
    figures = []
    stems = clip_filenames([c["name"] for c in chosen], "")  # file names safe everywhere, unique whatever the case
    for c, stem in zip(chosen, stems):
        loco, act = sources.get(c["locomotion"]), sources.get(c["action"])
        same = [d for d in per_clip if d["locomotion"] == c["locomotion"] and d["action"] == c["action"]]
        clips = [loco, act] + [db.read(d["name"]) for d in same]
        titles = [f"locomotion: {loco.name}", f"action: {act.name}"] + [d["method"] for d in same]
        if c["capture"]:
            clips.append(sources.get(c["capture"]))
            titles.append(f"captured: {c['capture']}")
        strip = folder / f"{stem}_filmstrip.png"
        render(clips, strip, titles=titles, frames=6, up_axis=spec.up_axis)
        if c.get("timing", "timewarp") != "timewarp":  # a standing action: no time alignment to plot
            figures.append((f"{c['name']} (standing action, {c['timing']}; acting: {c.get('acting') or 'none'})",
                            str(strip.relative_to(output.parent))))
            continue
        align = folder / f"{stem}_alignment.png"
        plot_alignment(loco, (moved or {}).get(c["action"], act), spec, align)  # the action as spliced
        figures.append((c["name"], str(strip.relative_to(output.parent))))
        figures.append((f"{c['name']}: time alignment", str(align.relative_to(output.parent))))
    return figures


def _lag_text(lag: float, ok: bool, band: tuple[float, float]) -> str:
    """A clip's arm-leg lag for the per-clip table, 3 decimals; one out of the captured ``band``
    names the bound it passes, with as many decimals as it takes to tell the two apart
    (``-0.0474 (out of range: below -0.0469)``)."""
    if lag is None or not math.isfinite(lag):
        return "-"
    if ok:
        return f"{lag:.3f}"
    below = lag < band[0]
    bound = band[0] if below else band[1]
    digits = 3
    while round(lag, digits) == round(bound, digits) and digits < 8:
        digits += 1
    return f"{lag:.{digits}f} (out of range: {'below' if below else 'above'} {bound:.{digits}f})"


def _markdown(path, spec, units, methods, agg, per_clip, phase_band, figures, max_rows, n_captured) -> str:
    lines = [f"# torchsplice evaluation: {md(path.name)}", "",
             f"{len(per_clip)} spliced clips, methods: {', '.join(map(md, methods))}; spec {md(spec.name)}, lengths in "
             f"{md(units)}.", "",
             "## Per method", "",
             f"| method | clips | foot speed in contact ({units}/s) | arm-leg lag, mean abs. (cycles) | lag within captured range | "
             f"posture kept ({units}) | ground-truth error ({units}) | ground-truth pairs | alignment cost |",
             "|---|---|---|---|---|---|---|---|---|"]
    for m in methods:
        a = agg[m]
        lines.append(f"| {md(m)} | {a['clips']} | {_fmt(a['foot_speed_in_contact'])} | {_fmt(a['phase'], 3)} | "
                     f"{100 * a['phase_in_range']:.0f}% | {_fmt(a['posture'])} | {_fmt(a['gt_error'])} | "
                     f"{a['gt_pairs']} | {_fmt(a['cost'])} |")
    lines += ["", "Foot speed in contact: mean horizontal foot speed while in ground contact (the evaluation's "
              "own measure, not the job's foot_skate column, GMD's ratio). Arm-leg lag: lag between each "
              "arm's swing and the opposite leg's swing, as a fraction of the gait cycle (0: the arm swings forward "
              "with the opposite leg); the captured source clips whose arms swing with their legs "
              f"(of {n_captured}) span {phase_band[0]:.3f} to {phase_band[1]:.3f}. Posture kept: distance between the "
              "result's and the action's mean shoulder offset from the pelvis in the heading frame. Ground-truth "
              "error: mean upper-body joint distance to the real capture of the same combination, each in its root "
              "heading frame after time alignment. Lower is better everywhere.", ""]
    lines += _ground_truth_section(per_clip, methods, units)
    lines += _standing_section(per_clip, methods, units, phase_band)
    lines += _retarget_section(per_clip, methods, units)
    lines += plausibility_section(per_clip, methods, md)
    if figures:
        lines += ["## Pictures", ""]
        lines += [f"**{md(title)}**\n\n![{md(title)}](<{file}>)\n" for title, file in figures]
    lines += ["## Per clip", ""]
    for m in methods:
        cs = [c for c in per_clip if c["method"] == m]
        lines += [f"### {md(m)}", "", "| clip | frames | foot speed in contact | arm-leg lag | posture kept | ground truth | error |",
                  "|---|---|---|---|---|---|---|"]
        for c in cs[:max_rows]:
            lines.append(f"| {md(c['name'])} | {c['frames']} | {_fmt(c['foot_speed_in_contact'])} | {_lag_text(c['phase'], c['phase_ok'], phase_band)}"
                         f" | {_fmt(c['posture'])} | "
                         f"{md(c['capture'] or '-')} | {_fmt(c['gt_error'])} |")
        if len(cs) > max_rows:
            lines.append(f"| ... {len(cs) - max_rows} more (the table stops at {max_rows} rows; every row: "
                         "evaluate's csv or json) | | | | | | |")
        lines.append("")
    return "\n".join(lines)
