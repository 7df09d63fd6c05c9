"""``torchsplice view``: one self-contained HTML file that plays a database's clips in 3D.

The file needs no server and no network: three.js (vendored from npm in ``vendor/``, see
``scripts/vendor_threejs.sh``) and the viewer's script are inlined, the three.js modules as
``data:`` URLs in an import map, and the clips as JSON in the page.

What goes in, per clip (:func:`clip_payload`):

- every drawn point's world position per frame (joints, end sites and the head's centre),
  from forward kinematics, turned into the viewer's frame: metres (the spec's units; a
  skeleton of unknown units is scaled to 1.7 m), Y up (``x = e2, y = up, z = e1`` of the
  file's right-handed axes, see :mod:`torchsplice.viz.camera`), the floor (the lowest point
  the clip reaches) at ``y = 0``;
- quantised per clip and axis to int16 around the middle of its range, with the offset and
  step to decode ``p = q * scale + offset`` (a step of 0.15 mm over a 10 m walk), little
  endian, base64: about 8 bytes per point per frame in the page, so 100 clips of 10 s of a
  28-point skeleton at 30 fps take about 8 MB;
- the bones (point pairs) with their side (0 centre, 1 left, 2 right, by joint name), the
  head's point and radius, the followed joint, the frame rate, role, labels and the splice
  job's columns (``locomotion``, ``action``, ``method`` ...).

For a spliced clip the page can show, in one click, its locomotion, its action and every
method's result for the same pair; the sources come from :mod:`torchsplice.viz.sources`
(``--sources``, the run record's inputs, or the database itself after ``--copy-sources``)
and are added to the page with the clips that need them.
"""

from __future__ import annotations

import base64
import json
import math
import re
import sys
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from ..core.errors import MotionError, TorchspliceError
from ..core.motion import Motion
from ..store.atomic import atomic_path
from ..store.database import MotionDatabase
from ..specs import DatasetSpec
from .camera import canonical_axes, check_up_axis
from .defaults import DEFAULT_MAX_CLIPS
from .stick_figure import figure_points, head_joint
from .sources import SourceClips, source_databases

__all__ = ["write_viewer", "build_viewer", "viewer_notes", "clip_payload", "quantize", "dequantize", "DEFAULT_MAX_CLIPS",
           "MAX_PAGE_FRAMES"]

MAX_PAGE_FRAMES = 60_000
"""The most frames one page holds, whatever the clips (about 14 MB of page; 33 minutes at 30
fps): clips past it are left out, as past ``max_clips``."""
"""Clips in a viewer when none are named (``--max-clips``): about 8 MB for clips of 10 s."""

_UNKNOWN_UNITS_HEIGHT = 1.7  # metres: a skeleton of unknown units is scaled to this size
_THREE_CORE_IMPORT = '"./three.core.min.js"'


# ---------------------------------------------------------------------------------------------
# Compact positions
# ---------------------------------------------------------------------------------------------


def quantize(points: np.ndarray) -> tuple[bytes, list[float], list[float]]:
    """``(T, P, 3)`` float positions as int16 little-endian bytes, with per-axis offset and step.

    Each axis is centred on the middle of its finite range and divided into steps of
    ``range / 65534``, so every finite value comes back (:func:`dequantize`) within half a
    step. Non-finite values are stored as the offset. Returns ``(bytes, offset[3], scale[3])``.
    """
    p = np.asarray(points, dtype=np.float64)
    finite = np.isfinite(p)
    lo = np.array([p[..., k][finite[..., k]].min() if finite[..., k].any() else 0.0 for k in range(3)])
    hi = np.array([p[..., k][finite[..., k]].max() if finite[..., k].any() else 0.0 for k in range(3)])
    offset = 0.5 * (lo + hi)
    scale = np.maximum((hi - lo) / 65534.0, 1e-9)
    q = np.where(finite, np.rint((p - offset) / scale), 0.0)
    q = np.clip(q, -32767, 32767).astype("<i2")
    return q.tobytes(), offset.tolist(), scale.tolist()


def dequantize(data: bytes, offset, scale, points: int) -> np.ndarray:
    """The inverse of :func:`quantize`: ``(T, points, 3)`` float64 from the int16 bytes."""
    q = np.frombuffer(data, dtype="<i2").astype(np.float64).reshape(-1, points, 3)
    return q * np.asarray(scale) + np.asarray(offset)


# ---------------------------------------------------------------------------------------------
# One clip
# ---------------------------------------------------------------------------------------------


def _metres_per_unit(spec: DatasetSpec | None, motion: Motion) -> float:
    """Metres per file unit: the spec's, or one that makes the skeleton 1.7 m when unknown."""
    mpu = spec.metres_per_unit if spec is not None else None
    if mpu:
        return float(mpu)
    return _UNKNOWN_UNITS_HEIGHT / max(float(motion.skeleton.size()), 1e-9)


def _jsonable(v):
    """Column values as plain JSON: numpy scalars to Python, non-finite floats to ``None``."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v


def clip_payload(motion: Motion, spec: DatasetSpec | None, info: dict | None = None, where: str = "") -> dict:
    """One clip as the page reads it (see the module docstring); ``info``: its database row.

    Positions: ``frames x points`` points of ``(x, y, z)`` metres, Y up, floor at 0,
    quantised by :func:`quantize` (``data`` is base64). ``bones``: ``[a, b, side]`` point
    pairs; ``head``: the head centre's point or -1, ``headRadius`` in metres; ``follow``:
    the point whose floor path the camera follows.
    """
    up = check_up_axis(spec.up_axis if spec is not None else 1)
    sk = motion.skeleton
    fig = figure_points(motion)
    pts = fig.points  # (T, P, 3) file units and axes
    head, head_size = head_joint(sk, pts, up)
    keep = sorted(set(int(i) for i in fig.drawn) | {int(fig.follow)})
    remap = {old: new for new, old in enumerate(keep)}
    sel = pts[:, keep]
    head_index = -1
    if head is not None:
        sel = np.concatenate([sel, head[:, None]], axis=1)
        head_index = sel.shape[1] - 1
    e1, e2, _ = canonical_axes(up)
    mpu = _metres_per_unit(spec, motion)
    world = sel[..., [e2, up, e1]] * mpu  # right-handed (e2, up, e1) is three.js's (x, y, z)
    heights = world[:, [remap[int(i)] for i in fig.drawn], 1]
    finite = np.isfinite(heights)
    world[..., 1] -= float(heights[finite].min()) if finite.any() else 0.0
    data, offset, scale = quantize(world)
    P = pts.shape[1]
    bones = []
    for side, idx in sorted(fig.lines.items()):
        pairs = idx.reshape(-1, 3)[:, :2]
        bones += [[remap[int(a)], remap[int(b)], int(side)] for a, b in pairs if a != P and b != P]
    info = dict(info or {})
    labels = info.pop("labels", None) or dict(motion.labels)
    columns = {k: _jsonable(v) for k, v in info.items()
               if k not in ("name", "role", "skeleton", "start", "length", "fps", "source")}
    return {
        "name": motion.name,
        "role": str(info.get("role", motion.role) or ""),
        "labels": {str(k): str(v) for k, v in labels.items()},
        "columns": columns,
        "db": where,
        "fps": float(motion.fps),
        "frames": int(motion.num_frames),
        "points": int(world.shape[1]),
        "offset": offset,
        "scale": scale,
        "data": base64.b64encode(data).decode("ascii"),
        "bones": bones,
        "head": head_index,
        "headRadius": float(0.5 * head_size * mpu),
        "follow": remap[int(fig.follow)],
        "size": float(sk.size() * mpu),
    }


# ---------------------------------------------------------------------------------------------
# Choosing the clips
# ---------------------------------------------------------------------------------------------


@dataclass
class ViewerContents:
    """What a viewer holds: ``names`` in page order, ``total`` clips in the database, whether
    ``--max-clips`` ``cut`` the selection, and source clips ``missing`` from every database."""

    names: list[str] = field(default_factory=list)
    total: int = 0
    cut: bool = False
    missing: list[str] = field(default_factory=list)
    size: int = 0


def _choose(db: MotionDatabase, table: dict, clips, sources: SourceClips, max_clips: int) -> ViewerContents:
    """The clips to put in the page, in order: the named ones (all clips without names, up to
    ``max_clips``), each spliced one followed by its locomotion, its action and the other
    methods' results for the pair (while under ``max_clips``; named clips always go in)."""
    names = [str(n) for n in table["name"]]
    roles = [str(r) for r in table["role"]]
    spliced = "locomotion" in table and "action" in table
    groups: dict[tuple[str, str], list[str]] = {}
    pair_of: dict[str, tuple[str, str]] = {}
    if spliced:
        for n, r, lo, ac in zip(names, roles, table["locomotion"], table["action"]):
            if r == "spliced" and str(lo) and str(ac):
                groups.setdefault((str(lo), str(ac)), []).append(n)
                pair_of[n] = (str(lo), str(ac))
    named = [str(c) for c in clips] if clips else []
    for c in named:
        db.index(c)  # a clear error for an unknown name
    out = ViewerContents(total=len(names))
    chosen: list[str] = []
    seen: set[str] = set()
    missing: set[str] = set()

    frames = [0]

    def length(n: str) -> int:
        if n in db:
            return int(table["length"][db.index(n)])
        where = sources.where(n)
        return where.clip_info(n)["length"] if where is not None else 0

    def add(n: str, force: bool = False) -> bool:
        if n in seen:
            return True
        if not force and len(chosen) >= max_clips:
            out.cut = True
            return False
        if n not in db and not sources.has(n):
            missing.add(n)
            return True
        f = length(n)
        if frames[0] + f > MAX_PAGE_FRAMES:
            if force:
                raise TorchspliceError(f"the clips named hold more than {MAX_PAGE_FRAMES:,} frames, the most one page "
                                       "plays smoothly; name fewer or shorter clips")
            out.cut = True
            return False
        frames[0] += f
        seen.add(n)
        chosen.append(n)
        return True

    for n in named or names:
        if not add(n, force=bool(named)):
            break
        if n in pair_of:
            lo, ac = pair_of[n]
            for m in [lo, ac] + groups[(lo, ac)]:
                add(m)
    if not named and len(chosen) < len(names):
        out.cut = True
    out.names = chosen
    out.missing = sorted(missing)
    return out


# ---------------------------------------------------------------------------------------------
# The page
# ---------------------------------------------------------------------------------------------


def _vendor(name: str) -> str:
    """A vendored three.js file's text (package data under ``torchsplice/viz/vendor``)."""
    try:
        return resources.files("torchsplice.viz").joinpath("vendor", name).read_text(encoding="utf-8")
    except OSError as exc:  # a broken installation
        raise TorchspliceError(f"the viewer's three.js file vendor/{name} is missing ({exc}); reinstall torchsplice") from None


def _data_url(js: str) -> str:
    return "data:text/javascript;base64," + base64.b64encode(js.encode("utf-8")).decode("ascii")


def _import_map() -> str:
    """The import map that defines ``three`` and its OrbitControls as inlined ``data:`` modules.

    ``three.module.min.js`` imports ``./three.core.min.js``, which a ``data:`` URL cannot
    resolve, so that specifier becomes the bare ``three-core``, mapped to the core module.
    """
    module = _vendor("three.module.min.js")
    if _THREE_CORE_IMPORT not in module:
        raise TorchspliceError("vendor/three.module.min.js does not import ./three.core.min.js; re-run scripts/vendor_threejs.sh")
    module = module.replace(_THREE_CORE_IMPORT, '"three-core"')
    imports = {
        "three-core": _data_url(_vendor("three.core.min.js")),
        "three": _data_url(module),
        "three/addons/controls/OrbitControls.js": _data_url(_vendor("OrbitControls.js")),
    }
    return json.dumps({"imports": imports})


def _script_json(obj) -> str:
    """JSON safe inside a ``<script>`` element (no ``</script>`` or ``<!--`` can end it)."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")


def build_viewer(database, clips=None, sources=None, max_clips: int = DEFAULT_MAX_CLIPS) -> tuple[str, ViewerContents]:
    """The viewer page for ``database`` as HTML text, and what it holds.

    Args:
        database: a motion database (``.h5``), spliced or not.
        clips: clip names to show (with the sources and other methods of the spliced ones);
            all clips, up to ``max_clips``, when empty.
        sources: databases holding the spliced clips' locomotions and actions; by default
            the run record's inputs, where they exist (and the database itself).
        max_clips: at most this many clips when none are named (sources counted).

    Raises:
        TorchspliceError: an unknown clip, an unreadable database, a broken installation.
    """
    if int(max_clips) < 1:
        raise TorchspliceError(f"{{max_clips}} must be at least 1, got {max_clips}", options=("max_clips",))
    database = Path(database)
    with MotionDatabase.open(database) as db:
        if len(db) == 0:
            raise TorchspliceError(f"{database}: holds no clip")
        srcs = source_databases(db, sources)
        try:
            lookup = SourceClips(srcs, db)
            table = db.table()
            contents = _choose(db, table, clips, lookup, int(max_clips))
            specs: dict[tuple[int, int], DatasetSpec] = {}
            payload = []
            for name in contents.names:
                home = db if name in db else lookup.where(name)
                info = home.clip_info(name)
                motion = home.read(name)
                try:
                    motion.check_finite()
                except TorchspliceError as exc:
                    raise MotionError(f"{home.path}: {exc.message}; the viewer shows only finite clips "
                                      "(name the others to view them)") from None
                key = (id(home), info["skeleton"])
                if key not in specs:
                    specs[key] = home.spec(info["skeleton"])
                where = "" if home is db else Path(home.path).name
                payload.append(clip_payload(motion, specs[key], info, where))
        finally:
            for s in srcs:
                s.close()
    data = {
        "database": database.name,
        "total": contents.total,
        "cut": contents.cut,
        "maxClips": int(max_clips),
        "missing": contents.missing,
        "clips": payload,
    }
    template = resources.files("torchsplice.viz").joinpath("viewer_template.html").read_text(encoding="utf-8")
    fill = {"__TITLE__": _html_escape(f"torchsplice view: {database.name}"), "__IMPORTMAP__": _import_map(),
            "__DATA__": _script_json(data)}
    # one pass: a placeholder inside a filled value (a database called __DATA__.h5) stays text
    html = re.sub("|".join(fill), lambda m: fill[m.group(0)], template)
    contents.size = len(html.encode("utf-8"))
    return html, contents


def _html_escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def write_viewer(database, output, clips=None, sources=None, max_clips: int = DEFAULT_MAX_CLIPS,
                 quiet: bool = False) -> ViewerContents:
    """Write the viewer page for ``database`` to ``output`` atomically (see :func:`build_viewer`).

    Says on stderr (unless ``quiet``) when ``max_clips`` cut the selection and which source
    clips no database holds. Returns what the page holds.
    """
    html, contents = build_viewer(database, clips, sources, max_clips)
    output = Path(output)
    with atomic_path(output) as tmp:  # an OSError becomes one line naming the file
        Path(tmp).write_text(html, encoding="utf-8")
    if not quiet:
        for line in viewer_notes(contents, database, max_clips):
            print(line, file=sys.stderr)
    return contents


def viewer_notes(contents: ViewerContents, database, max_clips: int, option_name=lambda o: o) -> list[str]:
    """The notes on what a page left out: ``max_clips`` cut the selection, source clips that no
    database holds. ``option_name(option)`` writes the options named (the command line: flags)."""
    out = []
    if contents.cut:
        out.append(f"note: the viewer holds {len(contents.names)} clips ({option_name('max_clips')} {max_clips}) of the "
                   f"{contents.total} in {Path(database).name}; name clips or raise {option_name('max_clips')} for others")
    if contents.missing:
        shown = ", ".join(contents.missing[:5]) + (" ..." if len(contents.missing) > 5 else "")
        out.append(f"note: {len(contents.missing)} source clips are in no database ({shown}); pass them with "
                   f"{option_name('sources')}")
    return out
