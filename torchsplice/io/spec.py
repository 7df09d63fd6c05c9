"""Dataset specs: which joints of a dataset's skeleton play which role, and what its clips are.

A spec is a small TOML file (the format is documented in ``datasets_spec/README.md``); the
shipped ones live in the package ``torchsplice.datasets_spec``. A spec names joints;
:meth:`DatasetSpec.bind` checks them against a :class:`~torchsplice.core.skeleton.Skeleton`
and turns them into integer indices (:class:`SkeletonRoles`). :meth:`DatasetSpec.clip_metadata`
gives a clip's role (``"locomotion"``, ``"action"`` or ``"both"``) and labels from its name.

Example::

    spec = load_spec("bandai_namco")
    roles = spec.bind(motion.skeleton)          # SkeletonRoles, integer joint indices
    role, labels = spec.clip_metadata("dataset-1_walk_proud_001")
    # ("both", {"dataset": "1", "content": "walk", "style": "proud", "take": "001"})

Where no spec fits, :func:`guess_spec` guesses one from common joint names and the hierarchy,
and :func:`detect_spec` picks a shipped spec for a file (or falls back on the guess). A guessed
spec says what it guessed: :meth:`DatasetSpec.guess_summary` (lines to print) and
:meth:`DatasetSpec.guessed_roles` (a JSON-able dict), kept through :meth:`DatasetSpec.to_json`.
Every problem is a one-line :class:`~torchsplice.core.errors.SpecError` naming the spec file.
"""

from __future__ import annotations

import fnmatch
import functools
import importlib.resources
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path, PurePath

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from ..core.errors import SpecError
from ..core.skeleton import POSITION_CHANNELS, Skeleton

__all__ = [
    "DatasetSpec", "RoleRule", "SkeletonRoles", "ROLES", "UNITS",
    "load_spec", "list_specs", "guess_spec", "detect_spec",
]

ROLES = ("locomotion", "action", "both")
"""Clip roles: lower-body source, upper-body source, or either."""

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048,
         "cmu": 0.0254 / 0.45, "unknown": None}
"""Length units a spec may name, with metres per unit (``None`` for ``"unknown"``).

``"cmu"`` is the CMU Graphics Lab unit (the ASF ``length 0.45``: 1 unit = 1/0.45 inch).
"""

_AXES = {"x": 0, "y": 1, "z": 2}
_PAIRS = ("hips", "knees", "feet", "shoulders")
_OPTIONAL_PAIRS = ("toes", "hands")
_SECTION_KEYS = {
    "dataset": {"name", "description", "up_axis", "units", "files"},
    "joints": {"root", "pelvis", "spine", "head", "upper_body", "lower_body", "guess",
               *_PAIRS, *_OPTIONAL_PAIRS},
    "clips": {"pattern", "default_role", "role", "reference", "ground_truth"},
}
_PACKAGE = "torchsplice.datasets_spec"
GENERIC = "generic"
_GUESS_KEYS = ("root", "pelvis", "spine", "head", "left_leg", "right_leg", "left_arm", "right_arm", "skipped")
"""Keys of a guessed spec's record (:meth:`DatasetSpec.guessed_roles`), in order."""
_GUESS_SINGLE = ("root", "pelvis", "head")


# --------------------------------------------------------------------------------------------
# data classes
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RoleRule:
    """One ``[[clips.role]]`` rule: clips it matches get ``role``.

    Attributes:
        role: ``"locomotion"``, ``"action"`` or ``"both"``.
        names: shell globs on the clip name (case-insensitive); empty matches every name.
        labels: ``((key, (value, ...)), ...)`` sorted by key: every key's label must be one of
            its values.
    """

    role: str
    names: tuple[str, ...] = ()
    labels: tuple[tuple[str, tuple[str, ...]], ...] = ()

    def matches(self, clip_name: str, labels: dict[str, str]) -> bool:
        """Whether a clip with this name and these labels falls under the rule."""
        lower = clip_name.lower()
        if self.names and not any(fnmatch.fnmatchcase(lower, g.lower()) for g in self.names):
            return False
        return all(labels.get(key) in values for key, values in self.labels)


@dataclass(frozen=True)
class SkeletonRoles:
    """A spec bound to one skeleton: integer joint indices by role.

    Attributes:
        root: the joint carrying the world trajectory.
        pelvis: the lowest upper-body joint (splicing edits its local rotation).
        spine: the chain from the pelvis upward.
        hips, knees, feet, shoulders: ``(left, right)`` indices.
        toes, hands: ``(left, right)`` or ``None``.
        head: index or ``None``.
        upper_body, lower_body: sorted, disjoint, together every joint.
        up_axis: 0, 1 or 2 (x, y, z).
        units: the spec's length unit (see :data:`UNITS`).
    """

    root: int
    pelvis: int
    spine: tuple[int, ...]
    hips: tuple[int, int]
    knees: tuple[int, int]
    feet: tuple[int, int]
    shoulders: tuple[int, int]
    toes: tuple[int, int] | None
    hands: tuple[int, int] | None
    head: int | None
    upper_body: tuple[int, ...]
    lower_body: tuple[int, ...]
    up_axis: int
    units: str


@dataclass(frozen=True)
class DatasetSpec:
    """A dataset spec: joint roles by name, axes and units, and clip-naming rules.

    Joint pairs are ``(left, right)`` tuples. A spec with ``guess=True`` (the shipped
    ``generic`` spec) names no joints: :meth:`bind` guesses them (see :func:`guess_spec`).

    Attributes:
        name: the spec's name (a spec file's stem).
        description: free text.
        up_axis: ``"x"``, ``"y"`` or ``"z"``.
        units: a key of :data:`UNITS`.
        files: file-name globs the spec is for (auto-detection).
        root, pelvis, spine, hips, knees, feet, shoulders, toes, hands, head: joint names.
        upper_body, lower_body: explicit joint lists, or ``None`` (derived from the pelvis).
        pattern: regex on the clip name whose named groups become labels, or ``None``.
        default_role: role of clips no rule matches.
        rules: :class:`RoleRule` s, first match wins.
        reference: ``((label, template), ...)``: the labels a plain-locomotion reference of
            an action carries (for the ``cpmc`` method); ``"{key}"`` in a template is the
            action's own label ``key``. ``None``: references must be named explicitly.
        ground_truth: ``(action conditions, locomotion conditions, capture templates, labels both
            must share)``: which
            captured clip shows an action's upper body during a locomotion (for evaluation);
            ``"{action.KEY}"`` / ``"{locomotion.KEY}"`` in a template are the sources' labels.
        guess: joints are guessed at :meth:`bind` time.
        path: the file it was loaded from, or ``None``.
        notes: remarks, e.g. what a guessed spec guessed and how.
        guessed: for a spec made by :func:`guess_spec`, its record ``((key, (joint, ...)), ...)``
            with every key of :meth:`guessed_roles`, in that order; ``()`` for any other spec
            (see :attr:`is_guessed`).
    """

    name: str
    description: str = ""
    up_axis: str = "y"
    units: str = "unknown"
    files: tuple[str, ...] = ()
    root: str = ""
    pelvis: str = ""
    spine: tuple[str, ...] = ()
    hips: tuple[str, str] = ("", "")
    knees: tuple[str, str] = ("", "")
    feet: tuple[str, str] = ("", "")
    shoulders: tuple[str, str] = ("", "")
    toes: tuple[str, str] | None = None
    hands: tuple[str, str] | None = None
    head: str | None = None
    upper_body: tuple[str, ...] | None = None
    lower_body: tuple[str, ...] | None = None
    pattern: str | None = None
    default_role: str = "locomotion"
    rules: tuple[RoleRule, ...] = ()
    reference: tuple[tuple[str, str], ...] | None = None
    ground_truth: tuple | None = None
    guess: bool = False
    path: Path | None = None
    notes: tuple[str, ...] = ()
    guessed: tuple[tuple[str, tuple[str, ...]], ...] = ()

    @property
    def where(self) -> str:
        """How messages name the spec: its file, or ``spec 'name'``."""
        return str(self.path) if self.path is not None else f"spec {self.name!r}"

    @property
    def metres_per_unit(self) -> float | None:
        """Metres per length unit, ``None`` when the units are unknown."""
        return UNITS[self.units]

    # -- binding -------------------------------------------------------------------------------
    def bind(self, skeleton: Skeleton) -> SkeletonRoles:
        """Check the named joints against ``skeleton`` and return their indices.

        Raises :class:`SpecError` naming the spec for an unknown joint (listing the skeleton's
        joints) or a hierarchy that contradicts the roles.
        """
        if self.guess:
            return guess_spec(skeleton, base=self).bind(skeleton)
        return _bind(self, skeleton)

    def resolve(self, skeleton: Skeleton) -> "DatasetSpec":
        """The spec with concrete joint names for ``skeleton``: itself, or for a ``guess``
        spec the guessed one (store this one, so that the guess is recorded)."""
        return guess_spec(skeleton, base=self) if self.guess else self

    def binds(self, skeleton: Skeleton) -> bool:
        """Whether :meth:`bind` succeeds on ``skeleton``."""
        try:
            self.bind(skeleton)
        except SpecError:
            return False
        return True

    # -- what a guess guessed ------------------------------------------------------------------
    @property
    def is_guessed(self) -> bool:
        """Whether :func:`guess_spec` made this spec (from one skeleton): it has a
        :attr:`guessed` record. ``False`` for hand-written specs and for the ``generic`` spec
        itself (``guess=True``: it guesses when bound; :meth:`resolve` gives the guessed one)."""
        return bool(self.guessed)

    def guessed_roles(self) -> dict:
        """What the guess found, as a JSON-able dict (``{}`` unless :attr:`is_guessed`)::

            {"root": "root", "pelvis": "spine05", "spine": ["spine05", ..., "neck03"],
             "head": "head",                        # or None
             "left_leg": ["upperleg01.L", "lowerleg01.L", "foot.L", "toe1-1.L"],  # no toe: 3
             "right_leg": [...],
             "left_arm": ["upperarm01.L", "lowerarm01.L", "wrist.L"],  # no hand: 2
             "right_arm": [...],
             "skipped": ["upperleg02.L", ...]}      # twist/roll/helper bones passed over

        Legs are thigh (hip), knee, foot (ankle) and toe; arms upper arm (shoulder), elbow
        (forearm) and hand (wrist). The same dict is the ``guessed`` object of :meth:`to_json`.
        """
        out: dict = {}
        for key, names in self.guessed:
            out[key] = (names[0] if names else None) if key in _GUESS_SINGLE else list(names)
        return out

    def guess_summary(self) -> list[str]:
        """What the guess found, one short line per item (``[]`` unless :attr:`is_guessed`)::

            root: root
            pelvis: spine05
            spine: spine05 > spine04 > spine03 > spine02 > spine01 > neck01 > neck02 > neck03
            head: head                               (or "head: none found")
            left leg: upperleg01.L > lowerleg01.L > foot.L > toe1-1.L
            right leg: ...
            left arm: upperarm01.L > lowerarm01.L > wrist.L
            right arm: ...
            skipped twist/roll/helper bones: upperleg02.L, ...   (only when some were)
        """
        lines = []
        for key, names in self.guessed:
            label = key.replace("_", " ")
            if key == "skipped":
                if names:
                    lines.append(f"skipped twist/roll/helper bones: {', '.join(names)}")
            elif key == "head" and not names:
                lines.append("head: none found")
            else:
                lines.append(f"{label}: {' > '.join(names)}")
        return lines

    # -- clips ---------------------------------------------------------------------------------
    def clip_metadata(self, clip_name: str) -> tuple[str, dict[str, str]]:
        """A clip's ``(role, labels)`` from its name (a file stem; a ``.bvh`` name works too).

        Labels are the named groups of ``pattern`` that matched (``re.search``); the role is
        the first matching rule's, else ``default_role``.
        """
        name = _clip_stem(clip_name)
        labels: dict[str, str] = {}
        if self.pattern is not None:
            m = re.search(self.pattern, name)
            if m:
                labels = {k: v for k, v in m.groupdict().items() if v is not None}
        role = next((r.role for r in self.rules if r.matches(name, labels)), self.default_role)
        return role, labels

    def reference_labels(self, labels: dict[str, str]) -> dict[str, str] | None:
        """Labels the reference of an action with ``labels`` must carry (``None`` if there is
        no rule, or the rule names a label the action lacks)."""
        if self.reference is None:
            return None
        try:
            return {k: v.format_map(labels) for k, v in self.reference}
        except (KeyError, ValueError, IndexError):
            return None

    def ground_truth_labels(self, locomotion: dict[str, str], action: dict[str, str]) -> dict[str, str] | None:
        """Labels of the captured clip that shows ``action``'s upper body during ``locomotion``
        (given both clips' labels), or ``None`` when the spec declares none for this pair."""
        if self.ground_truth is None:
            return None
        act_cond, loco_cond, capture, same = self.ground_truth
        if any(action.get(k) != v for k, v in act_cond) or any(locomotion.get(k) != v for k, v in loco_cond):
            return None
        if any(action.get(k) is None or action.get(k) != locomotion.get(k) for k in same):
            return None
        sides = {"action": action, "locomotion": locomotion}
        out = {}
        for key, template in capture:
            def sub(m):
                value = sides[m.group(1)].get(m.group(2))
                if value is None:
                    raise KeyError(m.group(0))
                return value
            try:
                out[key] = re.sub(r"\{(action|locomotion)\.([^{}]+)\}", sub, template)
            except KeyError:
                return None
        return out

    def matches_file(self, filename) -> bool:
        """Whether a file name (or its stem) matches one of the ``files`` globs."""
        base = PurePath(str(filename)).name
        return any(fnmatch.fnmatchcase(n, g) for g in self.files for n in (base, _clip_stem(base)))

    # -- serialisation -------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The spec as the TOML file's tables plus ``name`` (a copy of ``dataset.name``, for
        readers of stored specs), ``path``, ``notes`` and, for a guessed spec, ``guessed``
        (:meth:`guessed_roles`); unset optional keys left out."""
        return _to_dict(self)

    def to_json(self) -> str:
        """A JSON string :meth:`from_json` reads back into an equal spec."""
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "DatasetSpec":
        """Read :meth:`to_json` 's output (e.g. an HDF5 attribute)."""
        try:
            data = json.loads(text)
        except (TypeError, ValueError) as exc:
            raise SpecError(f"spec JSON: not valid JSON ({_one_line(exc)})") from None
        if not isinstance(data, dict):
            raise SpecError("spec JSON: expected an object")
        path = data.get("path")
        where = f"spec JSON ({path})" if isinstance(path, str) else "spec JSON"
        return _parse(data, where, from_json=True)


# --------------------------------------------------------------------------------------------
# loading
# --------------------------------------------------------------------------------------------
def list_specs() -> list[str]:
    """Names of the shipped specs (the ``*.toml`` stems in ``torchsplice.datasets_spec``)."""
    root = importlib.resources.files(_PACKAGE)
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_spec(name_or_path) -> DatasetSpec:
    """Load a shipped spec by name (``"bandai_namco"``) or a spec file by path.

    Anything ending in ``.toml``, holding a path separator, or a ``Path`` is taken as a file.
    Raises :class:`SpecError` for an unknown name (listing the shipped ones), an unreadable
    or malformed file (naming it and the problem).
    """
    text = str(name_or_path)
    if isinstance(name_or_path, PurePath) or text.endswith(".toml") or "/" in text or "\\" in text:
        return _load_file(Path(text))
    if text not in list_specs():
        shipped = ", ".join(list_specs())
        raise SpecError(f"unknown dataset spec {text!r}; shipped specs: {shipped} (or give a path to a .toml file)")
    return _load_shipped(text)


@functools.lru_cache(maxsize=None)
def _load_shipped(name: str) -> DatasetSpec:
    """A shipped spec, loaded once (specs are immutable)."""
    res = importlib.resources.files(_PACKAGE) / f"{name}.toml"
    return _parse_toml(res.read_text(encoding="utf-8"), Path(str(res)))


def _load_file(path: Path) -> DatasetSpec:
    """Read and parse a spec file; I/O and decoding problems become SpecErrors."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError(f"{path}: no such spec file") from None
    except UnicodeDecodeError:
        raise SpecError(f"{path}: not a UTF-8 text file") from None
    except OSError as exc:
        raise SpecError(f"{path}: cannot read spec file ({exc.strerror or exc})") from None
    return _parse_toml(text, path)


def _parse_toml(text: str, path: Path) -> DatasetSpec:
    """Parse a spec file's text; its ``[dataset] name`` must be the file's stem."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML: {_one_line(exc)}") from None
    spec = _parse(data, str(path), path=path)
    if spec.name != path.stem:
        raise SpecError(f"{path}: [dataset] name {spec.name!r} must equal the file's stem {path.stem!r}")
    return spec


# --------------------------------------------------------------------------------------------
# parsing and validation (TOML and JSON share it)
# --------------------------------------------------------------------------------------------
class _Table:
    """One table of a spec being parsed: typed getters that raise one-line SpecErrors."""

    def __init__(self, data: dict, where: str, section: str):
        self.data, self.where, self.section = data, where, section

    def fail(self, key: str, problem: str) -> SpecError:
        """A SpecError: ``FILE: [section] key: problem``."""
        return SpecError(f"{self.where}: [{self.section}] {key}: {problem}")

    def get(self, key: str, kind: type, required: bool = False, default=None, empty: bool = False):
        """``data[key]`` checked to be of ``kind`` (a string non-empty unless ``empty``);
        ``default`` when absent and optional."""
        if key not in self.data:
            if required:
                raise self.fail(key, "missing (required)")
            return default
        value = self.data[key]
        if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
            raise self.fail(key, f"expected {_kind_name(kind)}, got {_describe(value)}")
        if isinstance(value, str) and not empty and not value.strip():
            raise self.fail(key, "must not be empty")
        return value

    def names(self, key: str, required: bool = False) -> tuple[str, ...] | None:
        """A list of non-empty strings, as a tuple (``None`` when absent and optional)."""
        value = self.get(key, list, required)
        if value is None:
            return None
        if not value or not all(isinstance(v, str) and v.strip() for v in value):
            raise self.fail(key, f"expected a non-empty list of non-empty strings, got {_describe(value)}")
        return tuple(value)

    def pair(self, key: str, required: bool = False) -> tuple[str, str] | None:
        """A ``[left, right]`` pair of different joint names."""
        value = self.names(key, required)
        if value is None:
            return None
        if len(value) != 2:
            raise self.fail(key, f"expected two joint names [left, right], got {list(value)}")
        if value[0] == value[1]:
            raise self.fail(key, f"left and right are the same joint {value[0]!r}")
        return value

    def choice(self, key: str, options, default: str) -> str:
        """A string that must be one of ``options``."""
        value = self.get(key, str, default=default)
        if value not in options:
            raise self.fail(key, f"{value!r} is not one of {', '.join(map(repr, options))}")
        return value

    def check_keys(self, allowed) -> None:
        """Refuse keys the format does not know (catches typos)."""
        extra = sorted(set(self.data) - set(allowed))
        if extra:
            raise self.fail(extra[0], f"unknown key (allowed: {', '.join(sorted(allowed))})")


def _parse(data: dict, where: str, path: Path | None = None, from_json: bool = False) -> DatasetSpec:
    """Validate the tables of a spec file (or its JSON form) into a :class:`DatasetSpec`."""
    allowed = {"dataset", "joints", "clips"} | ({"name", "path", "notes", "guessed"} if from_json else set())
    extra = sorted(set(data) - allowed)
    if extra:
        raise SpecError(f"{where}: unknown top-level key or table [{extra[0]}] (allowed: dataset, joints, clips)")
    dataset = _section(data, where, "dataset", required=True)
    joints = _section(data, where, "joints", required=True)
    clips = _section(data, where, "clips", required=False)
    fields_ = {**_parse_dataset(dataset), **_parse_joints(joints), **_parse_clips(clips)}
    notes, guessed = (), ()
    if from_json:
        path, notes = _json_extras(data, where, fields_["name"])
        guessed = _json_guessed(data.get("guessed"), where)
    return DatasetSpec(**fields_, path=path, notes=notes, guessed=guessed)


def _section(data: dict, where: str, name: str, required: bool) -> _Table:
    """The table ``[name]`` with its keys checked."""
    value = data.get(name, {} if not required else None)
    if value is None:
        raise SpecError(f"{where}: missing table [{name}]")
    if not isinstance(value, dict):
        raise SpecError(f"{where}: [{name}] must be a table, got {_describe(value)}")
    table = _Table(value, where, name)
    table.check_keys(_SECTION_KEYS[name])
    return table


def _parse_dataset(t: _Table) -> dict:
    """Fields of ``[dataset]``."""
    return {
        "name": t.get("name", str, required=True),
        "description": t.get("description", str, default="", empty=True),
        "up_axis": t.choice("up_axis", tuple(_AXES), default="y"),
        "units": t.choice("units", tuple(UNITS), default="unknown"),
        "files": t.names("files") or (),
    }


def _parse_joints(t: _Table) -> dict:
    """Fields of ``[joints]`` (only ``guess`` for a guessing spec)."""
    if t.get("guess", bool, default=False):
        named = sorted(set(t.data) - {"guess"})
        if named:
            raise t.fail(named[0], "a spec with guess = true names no joints")
        return {"guess": True}
    out = {"root": t.get("root", str, required=True), "pelvis": t.get("pelvis", str, required=True),
           "spine": t.names("spine", required=True), "head": t.get("head", str),
           "upper_body": t.names("upper_body"), "lower_body": t.names("lower_body")}
    out.update({k: t.pair(k, required=True) for k in _PAIRS})
    out.update({k: t.pair(k) for k in _OPTIONAL_PAIRS})
    if not out["spine"] or out["spine"][0] != out["pelvis"]:
        raise t.fail("spine", f"must start at the pelvis {out['pelvis']!r} and go upward, got {list(out['spine'])}")
    return out


def _parse_clips(t: _Table) -> dict:
    """Fields of ``[clips]``: pattern (compiled once to check it), default role, rules."""
    pattern = t.get("pattern", str)
    if pattern is not None:
        try:
            re.compile(pattern)
        except re.error as exc:
            raise t.fail("pattern", f"not a valid regular expression ({exc})") from None
    rules = t.get("role", list, default=[])
    reference = t.get("reference", dict)
    if reference is not None:
        bad = [k for k, v in reference.items() if not isinstance(v, str)]
        if not reference or bad:
            raise t.fail("reference", "must be a table of label = \"value or {label} template\" strings")
    ground_truth = t.get("ground_truth", dict)
    if ground_truth is not None:
        ground_truth = _parse_ground_truth(ground_truth, t)
    return {
        "pattern": pattern,
        "default_role": t.choice("default_role", ROLES, default="locomotion"),
        "rules": tuple(_parse_rule(r, i, t.where) for i, r in enumerate(rules)),
        "reference": None if reference is None else tuple(sorted(reference.items())),
        "ground_truth": ground_truth,
    }


def _parse_ground_truth(table: dict, t) -> tuple:
    """``[clips.ground_truth]``: ``((("action", k, v), ...), (("locomotion", k, v), ...), ((k, template), ...))``."""
    extra = set(table) - {"action", "locomotion", "capture", "same"}
    capture = table.get("capture")
    if extra or not isinstance(capture, dict) or not capture:
        raise t.fail("ground_truth", "must hold a non-empty 'capture' table and optional 'action', 'locomotion' and 'same'")
    same = table.get("same", [])
    if not isinstance(same, list) or not all(isinstance(k, str) for k in same):
        raise t.fail("ground_truth", "'same' must be a list of label names")
    conds = []
    for side in ("action", "locomotion"):
        cond = table.get(side, {})
        if not isinstance(cond, dict) or not all(isinstance(v, str) for v in cond.values()):
            raise t.fail("ground_truth", f"'{side}' must be a table of label = \"value\" strings")
        conds.append(tuple(sorted(cond.items())))
    if not all(isinstance(v, str) for v in capture.values()):
        raise t.fail("ground_truth", "'capture' must be a table of label = \"value or {side.label} template\" strings")
    return conds[0], conds[1], tuple(sorted(capture.items())), tuple(sorted(same))


def _parse_rule(rule, i: int, where: str) -> RoleRule:
    """The ``i``-th ``[[clips.role]]`` rule."""
    section = f"clips.role #{i + 1}"
    if not isinstance(rule, dict):
        raise SpecError(f"{where}: [{section}] must be a table ([[clips.role]]), got {_describe(rule)}")
    t = _Table(rule, where, section)
    t.check_keys({"role", "names", "labels"})
    role = t.get("role", str, required=True)
    if role not in ROLES:
        raise t.fail("role", f"{role!r} is not one of {', '.join(map(repr, ROLES))}")
    labels = t.get("labels", dict, default={})
    if "names" not in rule and not labels:
        raise t.fail("names", "a rule needs names or labels (or both)")
    lt = _Table(labels, where, f"{section} labels")
    return RoleRule(role, t.names("names") or (), tuple((k, lt.names(k, required=True)) for k in sorted(labels)))


def _json_extras(data: dict, where: str, name: str) -> tuple[Path | None, tuple[str, ...]]:
    """``path`` and ``notes`` of a spec's JSON form (its top-level ``name`` must match)."""
    if data.get("name", name) != name:
        raise SpecError(f"{where}: name {data.get('name')!r} differs from [dataset] name {name!r}")
    path, notes = data.get("path"), data.get("notes", [])
    if path is not None and not isinstance(path, str):
        raise SpecError(f"{where}: path must be a string")
    if not isinstance(notes, list) or not all(isinstance(n, str) for n in notes):
        raise SpecError(f"{where}: notes must be a list of strings")
    return (Path(path) if path is not None else None), tuple(notes)


def _json_guessed(value, where: str) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """The ``guessed`` object of a spec's JSON form (absent: ``()``), checked."""
    if value is None:
        return ()
    if not isinstance(value, dict):
        raise SpecError(f"{where}: guessed: expected an object, got {_describe(value)}")
    extra = sorted(set(value) - set(_GUESS_KEYS))
    if extra:
        raise SpecError(f"{where}: guessed: unknown key {extra[0]!r} (allowed: {', '.join(_GUESS_KEYS)})")
    out = []
    for key in _GUESS_KEYS:
        if key not in value:
            continue
        v = value[key]
        if key in _GUESS_SINGLE:
            if not (v is None or (isinstance(v, str) and v)) or (v is None and key != "head"):
                raise SpecError(f"{where}: guessed: {key}: expected a joint name, got {_describe(v)}")
            out.append((key, () if v is None else (v,)))
        else:
            if not isinstance(v, list) or not all(isinstance(n, str) and n for n in v):
                raise SpecError(f"{where}: guessed: {key}: expected a list of joint names, got {_describe(v)}")
            out.append((key, tuple(v)))
    return tuple(out)


def _to_dict(spec: DatasetSpec) -> dict:
    """See :meth:`DatasetSpec.to_dict`."""
    dataset = {"name": spec.name, "description": spec.description, "up_axis": spec.up_axis,
               "units": spec.units, **({"files": list(spec.files)} if spec.files else {})}
    if spec.guess:
        joints = {"guess": True}
    else:
        keys = ("root", "pelvis", "spine", "head", "upper_body", "lower_body", *_PAIRS, *_OPTIONAL_PAIRS)
        joints = {k: getattr(spec, k) for k in keys if getattr(spec, k) is not None}
        joints = {k: list(v) if isinstance(v, tuple) else v for k, v in joints.items()}
    rules = [{"role": r.role, **({"names": list(r.names)} if r.names else {}),
              **({"labels": {k: list(v) for k, v in r.labels}} if r.labels else {})} for r in spec.rules]
    clips = {"default_role": spec.default_role, "role": rules}
    if spec.pattern is not None:
        clips["pattern"] = spec.pattern
    if spec.reference is not None:
        clips["reference"] = dict(spec.reference)
    if spec.ground_truth is not None:
        act, loco, cap, same = spec.ground_truth
        clips["ground_truth"] = {"action": dict(act), "locomotion": dict(loco), "capture": dict(cap), "same": list(same)}
    out = {"name": spec.name, "dataset": dataset, "joints": joints, "clips": clips, "notes": list(spec.notes)}
    if spec.path is not None:
        out["path"] = str(spec.path)
    if spec.guessed:
        out["guessed"] = spec.guessed_roles()
    return out


# --------------------------------------------------------------------------------------------
# binding
# --------------------------------------------------------------------------------------------
def _bind(spec: DatasetSpec, sk: Skeleton) -> SkeletonRoles:
    """Indices of the spec's joints in ``sk``, with the hierarchy checks of :meth:`DatasetSpec.bind`."""
    def idx(key, name):
        if name not in sk.names:
            raise SpecError(f"{spec.where}: [joints] {key} names joint {name!r}, which the skeleton "
                            f"does not have; its joints: {', '.join(sk.names)}")
        return sk.names.index(name)

    def pair(key):
        value = getattr(spec, key)
        return None if value is None else (idx(key, value[0]), idx(key, value[1]))

    roles = dict(root=idx("root", spec.root), pelvis=idx("pelvis", spec.pelvis),
                 spine=tuple(idx("spine", n) for n in spec.spine),
                 head=None if spec.head is None else idx("head", spec.head),
                 **{k: pair(k) for k in (*_PAIRS, *_OPTIONAL_PAIRS)})
    _check_hierarchy(spec, sk, roles)
    upper, lower = _body_split(spec, sk, roles["pelvis"], idx)
    return SkeletonRoles(**roles, upper_body=upper, lower_body=lower,
                         up_axis=_AXES[spec.up_axis], units=spec.units)


def _is_ancestor(parents: tuple[int, ...], a: int, b: int) -> bool:
    """Whether joint ``a`` is ``b`` or one of its ancestors."""
    while b >= 0:
        if b == a:
            return True
        b = parents[b]
    return False


def _check_hierarchy(spec: DatasetSpec, sk: Skeleton, r: dict) -> None:
    """Refuse roles the hierarchy contradicts (each problem named with its joints)."""
    anc = functools.partial(_is_ancestor, sk.parents)
    name = sk.names

    def fail(problem):
        raise SpecError(f"{spec.where}: [joints] {problem}")

    if not anc(r["root"], r["pelvis"]):
        fail(f"root {name[r['root']]!r} must be the pelvis {name[r['pelvis']]!r} or one of its ancestors")
    for key in ("hips", "knees", "feet"):
        for j in r[key]:
            if anc(r["pelvis"], j):
                fail(f"{key}: {name[j]!r} lies below the pelvis {name[r['pelvis']]!r}; the pelvis must "
                     "be an upper-body joint, not an ancestor of the legs")
            if key == "hips" and not anc(r["root"], j):
                fail(f"hips: {name[j]!r} is not below the root {name[r['root']]!r}")
    chains = [("hips", "knees"), ("knees", "feet"), ("feet", "toes"), ("shoulders", "hands")]
    for upper, lower in chains:
        if r[upper] is None or r[lower] is None:
            continue
        for side in (0, 1):
            a, b = r[upper][side], r[lower][side]
            if a == b or not anc(a, b):
                fail(f"{lower}: {name[b]!r} must lie below {upper} {name[a]!r}")
    for a, b in zip(r["spine"], r["spine"][1:]):
        if a == b or not anc(a, b):
            fail(f"spine: {name[b]!r} must lie below {name[a]!r} (list the spine from the pelvis upward)")


def _body_split(spec: DatasetSpec, sk: Skeleton, pelvis: int, idx) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Upper- and lower-body joint sets: explicit lists, or the pelvis's subtree and the rest."""
    every = set(range(sk.num_joints))
    upper = set(idx("upper_body", n) for n in spec.upper_body) if spec.upper_body is not None else None
    lower = set(idx("lower_body", n) for n in spec.lower_body) if spec.lower_body is not None else None
    if upper is None:
        upper = set(sk.descendants(pelvis)) if lower is None else every - lower
    if lower is None:
        lower = every - upper
    both, missing = upper & lower, every - upper - lower
    if both or missing:
        bad = sorted(both or missing)
        what = "in both upper_body and lower_body" if both else "in neither upper_body nor lower_body"
        raise SpecError(f"{spec.where}: [joints] joints {[sk.names[j] for j in bad]} are {what}")
    if pelvis not in upper:
        raise SpecError(f"{spec.where}: [joints] upper_body must contain the pelvis {sk.names[pelvis]!r}")
    return tuple(sorted(upper)), tuple(sorted(lower))


# --------------------------------------------------------------------------------------------
# guessing and detection
# --------------------------------------------------------------------------------------------
_KNEE = {"knee", "leg", "lowerleg", "lowleg", "loleg", "calf", "shin"}
_THIGH = {"upleg", "upperleg", "uleg", "thigh", "hip"}
_FOOT = {"foot", "ankle"}
_TOE = {"toe", "toes", "toebase", "ball", "foottoe"}
_ELBOW = {"elbow", "forearm", "lowerarm", "lowarm", "loarm"}
_UPPERARM = {"upperarm", "uparm", "arm", "humerus"}
_HAND = {"hand", "wrist"}
_HEAD = {"head"}
_PARTS = _KNEE | _THIGH | _FOOT | _TOE | _ELBOW | _UPPERARM | _HAND | _HEAD | {"collar", "clavicle", "shoulder"}
_IGNORED = {"bip", "joint", "jnt", "def", "bone", "mixamorig", "j"}
_SIDES = {"l": "L", "left": "L", "lft": "L", "r": "R", "right": "R", "rgt": "R"}
_TWIST_WORDS = ("twist", "helper")
"""Words that make a joint a twist/helper bone wherever they stand in its name (``ForeTwist``);
``roll`` counts as a word of its own or at the end (``LeftArmRoll``, ``upperarm_roll_l``,
``l_forearmroll``)."""
_TWIST_MAX_BEND = 25.0
"""Degrees: a numbered continuation (``upperleg01.L > upperleg02.L``) bending more than this
away from its parent's direction in the rest pose starts a new segment, not a twist bone."""
_LEGS_HANG = 0.5
"""The rest pose shows the legs hanging down when each foot is below its hip by at least this
fraction of the leg's length along the bones; else the quadruped check cannot tell."""
_REACH = 0.25
"""A front limb reaches the ground when its lowest point is within this fraction of the hip
height (above the feet) of the feet's level."""
_UPRIGHT = 60.0
"""Degrees: a spine (pelvis to chest) further than this from the up axis is horizontal."""


def _name_words(name: str) -> list[str]:
    """Lower-case words of a joint name, namespace (``mixamorig:``) dropped, digits kept."""
    name = re.split(r"[:|]", name)[-1]
    return [t.lower() for t in re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+", name)]


def _numbered_base(name: str) -> str:
    """A joint name without its numbers: ``upperleg02.L`` -> ``upperleg.l``,
    ``DEF-thigh.L.001`` -> ``def-thigh.l``."""
    return re.sub(r"[\s._-]*\d+", "", name).strip(" ._-").lower()


def _side_and_core(name: str) -> tuple[str | None, str]:
    """``("L" | "R" | None, core)`` of a joint name, e.g. ``"LeftUpLeg"`` -> ``("L", "upleg")``.

    Namespaces (``mixamorig:``) and digits are dropped; sides are read from ``Left``/``L``/``l_``
    /``_L`` tokens, or a glued ``l``/``r`` prefix before a body-part word (``lhand``).
    """
    tokens = [t for t in _name_words(name) if not t.isdigit() and t not in _IGNORED]
    sides = {_SIDES[t] for t in tokens if t in _SIDES}
    core = "".join(t for t in tokens if t not in _SIDES)
    if len(sides) == 1:
        return sides.pop(), core
    for word, side in (("left", "L"), ("right", "R")):
        if core.startswith(word) and len(core) > len(word):
            return side, core[len(word):]
    if len(core) > 1 and core[0] in "lr" and core[1:] in _PARTS:
        return core[0].upper(), core[1:]
    return None, core


class _Guesser:
    """Finds limbs on one skeleton by name, then derives their neighbours from the hierarchy,
    passing over twist/roll/helper bones (see :meth:`is_twist`)."""

    def __init__(self, sk: Skeleton):
        self.sk = sk
        self.parsed = [_side_and_core(n) for n in sk.names]
        self.words = [_name_words(n) for n in sk.names]
        self.rest = sk.rest_positions()[0]
        self.notes: list[str] = []

    def fail(self, problem: str, joints: bool = True) -> SpecError:
        """A SpecError saying what could not be guessed, listing the joints unless told not to."""
        listed = f"; its joints: {', '.join(self.sk.names)}" if joints else ""
        return SpecError(f"cannot guess the joint roles of this skeleton: {problem}; write a dataset "
                         f"spec (see datasets_spec/README.md){listed}")

    def named(self, side: str | None, parts: set[str]) -> list[int]:
        """Joints whose side is ``side`` and whose core is one of ``parts``, in index order."""
        return [j for j, (s, c) in enumerate(self.parsed) if s == side and c in parts]

    def only_child(self, j: int) -> int | None:
        """``j``'s child if it has exactly one."""
        kids = self.sk.children(j)
        return kids[0] if len(kids) == 1 else None

    def is_twist(self, j: int, toward: int | None = None) -> bool:
        """Whether ``j`` is a twist, roll or helper bone inside a limb segment rather than the
        joint that starts the next segment: named so (``twist``, ``roll``, ``helper``:
        ``upperarm_twist_01_l``, ``LeftArmRoll``, ``Bip01 L ForeTwist``), or a numbered
        continuation of its parent (``upperleg01.L > upperleg02.L``, ``DEF-thigh.L >
        DEF-thigh.L.001``) that carries on in its parent's direction toward ``toward`` (the
        joint the limb continues to) in the rest pose, within :data:`_TWIST_MAX_BEND` degrees;
        where the rest pose cannot tell (no ``toward``, a zero-length bone), the name decides."""
        core, words = self.parsed[j][1], self.words[j]
        if any(w in core for w in _TWIST_WORDS) or "roll" in words or core.endswith("roll"):
            return True
        p = self.sk.parents[j]
        name = self.sk.names[j]
        if p < 0 or not re.search(r"\d", name) or _numbered_base(name) != _numbered_base(self.sk.names[p]):
            return False
        if toward is None:
            return True
        a, b = self.rest[j] - self.rest[p], self.rest[toward] - self.rest[j]
        na, nb = float(a.norm()), float(b.norm())
        if na <= 1e-9 or nb <= 1e-9:
            return True
        return float(a @ b) / (na * nb) >= math.cos(math.radians(_TWIST_MAX_BEND))

    def segment_top(self, j: int) -> int:
        """The joint that starts the segment ``j`` hangs from: ``j``'s parent, or above the
        twist bones in line between them (``lowerleg01.L`` -> ``upperleg01.L``, not
        ``upperleg02.L``); ``-1`` above the root."""
        below, p = j, self.sk.parents[j]
        while p >= 0 and self.sk.parents[p] >= 0 and self.is_twist(p, below):
            below, p = p, self.sk.parents[p]
        return p

    def next_segment(self, j: int, parts: set[str]) -> int | None:
        """The child of ``j`` that starts the next segment: the one named like ``parts``; else,
        when ``j``'s only children with descendants are twist bones in line (``lowerleg01.L >
        lowerleg02.L > foot.L``, ``LeftForeArm > LeftForeArmRoll > LeftHand``), the next
        segment below that one; else the only child that is not a twist bone; else ``None``."""
        kids = self.sk.children(j)
        named = [c for c in kids if self.parsed[c][1] in parts]
        if named:
            return named[0]
        plain = [c for c in kids if not self.is_twist(c, self.only_child(c))]
        inline = [c for c in kids if c not in plain and self.sk.children(c)]
        if not plain and len(inline) == 1:
            return self.next_segment(inline[0], parts)
        return plain[0] if len(plain) == 1 else None

    def middle(self, side: str, mid: set[str], upper: set[str], lower: set[str], what: str) -> int:
        """The knee or elbow of one side: by its own name, else below an upper / above a lower
        joint (twist bones never count)."""
        named = [j for j in self.named(side, mid) if self.sk.children(j) and self.sk.parents[j] >= 0]
        plain = [j for j in named if not self.is_twist(j, self.only_child(j))]
        if plain or named:
            return (plain or named)[0]
        depth = lambda j: len(self._path_up(j))  # noqa: E731
        uppers = [j for j in self.named(side, upper) if not self.is_twist(j, self.only_child(j))]
        for j in sorted(uppers, key=depth, reverse=True):
            c = self.next_segment(j, set())
            if c is not None and self.sk.children(c):
                self.notes.append(f"{what} {self.sk.names[c]}: the child of {self.sk.names[j]}")
                return c
        for j in sorted(self.named(side, lower), key=depth):
            p = self.segment_top(j)
            if p >= 0 and self.sk.parents[p] >= 0:
                self.notes.append(f"{what} {self.sk.names[p]}: the parent of {self.sk.names[j]}")
                return p
        side_word = "left" if side == "L" else "right"
        raise self.fail(f"no {side_word} {what} found (looked for joint names like {', '.join(sorted(mid))})")

    def limb(self, mid: set[str], upper: set[str], lower: set[str], end: set[str], what: str,
             end_required: bool = True):
        """``(upper, middle, lower)`` index pairs (left, right) of the legs or arms; ``lower``
        is ``None`` when it cannot be told and is not required."""
        mids = tuple(self.middle(s, mid, upper, lower, what) for s in ("L", "R"))
        tops = tuple(self.segment_top(m) for m in mids)
        ends = tuple(self.next_segment(m, end) for m in mids)
        if None in ends and not end_required:
            self.notes.append(f"no {'/'.join(sorted(end))} joints found below the {what}s")
            return tops, mids, None
        if None in ends:
            m = mids[ends.index(None)]
            raise self.fail(f"cannot tell which child of the {what} {self.sk.names[m]!r} continues the limb")
        return tops, mids, ends

    def _path_up(self, j: int) -> list[int]:
        """``j`` and its ancestors, bottom-up."""
        path = []
        while j >= 0:
            path.append(j)
            j = self.sk.parents[j]
        return path

    def common_ancestor(self, joints) -> int:
        """The lowest joint that is an ancestor-or-self of every joint in ``joints``."""
        paths = [self._path_up(j) for j in joints]
        shared = set(paths[0]).intersection(*paths[1:])
        return next(j for j in paths[0] if j in shared)

    def toward(self, top: int, j: int) -> int:
        """The child of ``top`` on the path down to ``j``."""
        path = self._path_up(j)
        return path[path.index(top) - 1]


def guess_spec(skeleton: Skeleton, base: DatasetSpec | None = None) -> DatasetSpec:
    """Guess a spec for ``skeleton`` from common joint names and the hierarchy.

    Knees (``knee``, ``leg``, ``lowerleg``, ``calf``, ``shin``...) and elbows (``elbow``,
    ``forearm``, ``lowerarm``...) are found by name and side (``Left``/``L``/``l_``/``_L``...);
    failing that, below a thigh (``upleg``, ``thigh``, ``hip``...) or upper arm, or above a
    foot or hand. Hips and shoulders are the joints above them (so the shoulder is the
    glenohumeral joint, never a clavicle), feet and hands the joints below them (named like
    ``foot``/``hand``, else the only child), toes the joint below the foot.

    Twist, roll and helper bones never take a role: each role goes to the joint that *starts*
    the next segment. A twist bone is one named so (``twist``, ``roll``, ``helper``), or a
    numbered continuation of its parent that carries on in the parent's direction in the rest
    pose (MakeHuman's ``upperleg01.L > upperleg02.L > lowerleg01.L > lowerleg02.L > foot.L``:
    thigh ``upperleg01.L``, knee ``lowerleg01.L``, foot ``foot.L``; Rigify's ``DEF-thigh.L >
    DEF-thigh.L.001``). Climbing from a knee or elbow, twist bones in line are passed (from
    ``LeftForeArm`` up past ``LeftArmRoll``: shoulder ``LeftArm``); going down, a twist bone in
    line is passed (``LeftForeArm > LeftForeArmRoll > LeftHand``) and one on a side branch
    (Unreal's ``calf_twist_01_l`` beside ``foot_l``) is not a candidate. Knee or elbow
    candidates that are twist bones come last. The bones passed over are recorded.

    The root is the lowest common ancestor of legs and arms (or its nearest ancestor with
    position channels), the pelvis its child toward the shoulders, the spine the chain from the
    pelvis to the head (``head``). Up axis, units and clip rules come from ``base`` (the
    shipped ``generic`` spec by default).

    Only humanoids are guessed. Where the rest pose shows the legs hanging down along the up
    axis (each foot below its hip by half the leg's length or more), a skeleton whose four
    limbs all reach the ground (the arms end within a quarter of the hip height of the feet's
    level) or whose spine, pelvis to chest, lies more than 60 degrees from the up axis is
    refused: a quadruped (the Truebones elephant, whose front legs are named like arms) or a
    creature with a level spine. A rest pose that does not show the legs hanging down (LAFAN1,
    Bandai Namco: every bone along +X) leaves the check out, as the notes say.

    What was guessed is recorded in :attr:`DatasetSpec.guessed` (see
    :meth:`DatasetSpec.guessed_roles` and :meth:`DatasetSpec.guess_summary`) and how, one line
    each, in ``notes``.

    Raises :class:`SpecError` saying what could not be found, or why the skeleton does not look
    like a humanoid.
    """
    base = base or load_spec(GENERIC)
    g = _Guesser(skeleton)
    hips, knees, feet = g.limb(_KNEE, _THIGH, _FOOT, _FOOT, "knee")
    shoulders, elbows, hands = g.limb(_ELBOW, _UPPERARM, _HAND, _HAND, "elbow", end_required=False)
    toes = tuple(g.next_segment(f, _TOE) for f in feet)
    top = g.common_ancestor([*hips, *shoulders])
    if top in (*hips, *shoulders):
        raise g.fail(f"the legs and arms do not branch apart ({skeleton.names[top]!r} is a limb joint)")
    chest = g.common_ancestor(shoulders)
    if chest == top:
        raise g.fail(f"the arms branch from {skeleton.names[top]!r}, the same joint as the legs, so no "
                     "joint can be the pelvis")
    pelvis = g.toward(top, chest)
    root = _trajectory_joint(skeleton, top)
    heads = [j for j, (_, core) in enumerate(g.parsed) if core in _HEAD and _is_ancestor(skeleton.parents, pelvis, j)]
    head = heads[0] if heads else None
    spine = _chain(skeleton, pelvis, skeleton.parents[head] if head is not None else chest)
    problem, posture = _posture(skeleton, _AXES[base.up_axis], pelvis, chest, head, hips, feet, shoulders)
    if problem is not None:
        raise g.fail(problem, joints=False)
    n = skeleton.names
    pair = lambda p: (n[p[0]], n[p[1]])  # noqa: E731
    names = lambda js: tuple(n[j] for j in js)  # noqa: E731
    legs = [(hips[s], knees[s], feet[s]) + ((toes[s],) if None not in toes else ()) for s in (0, 1)]
    arms = [(shoulders[s], elbows[s]) + ((hands[s],) if hands else ()) for s in (0, 1)]
    skipped = [j for limb in legs + arms for a, b in zip(limb, limb[1:]) for j in _chain(skeleton, a, b)[1:-1]]
    guessed = (("root", (n[root],)), ("pelvis", (n[pelvis],)), ("spine", names(spine)),
               ("head", (n[head],) if head is not None else ()), ("left_leg", names(legs[0])),
               ("right_leg", names(legs[1])), ("left_arm", names(arms[0])), ("right_arm", names(arms[1])),
               ("skipped", names(skipped)))
    spec = DatasetSpec(
        name=base.name, description=base.description, up_axis=base.up_axis, units=base.units,
        files=base.files, root=n[root], pelvis=n[pelvis], spine=tuple(n[j] for j in spine),
        hips=pair(hips), knees=pair(knees), feet=pair(feet), shoulders=pair(shoulders),
        toes=pair(toes) if None not in toes else None, hands=pair(hands) if hands else None,
        head=n[head] if head is not None else None, pattern=base.pattern,
        default_role=base.default_role, rules=base.rules, path=None,
        notes=tuple(_guess_notes(skeleton, g.notes, root, top, pelvis, head, toes, dict(
            hips=hips, knees=knees, feet=feet, shoulders=shoulders, elbows=elbows, hands=hands or (None, None)),
            skipped, posture)),
        guessed=guessed,
    )
    try:
        spec.bind(skeleton)
    except SpecError as exc:
        raise g.fail(f"the guess does not fit ({exc})") from None
    return spec


def _trajectory_joint(sk: Skeleton, top: int) -> int:
    """``top`` if its position is animated, else its nearest ancestor that is, else joint 0."""
    j = top
    while j >= 0:
        if any(c in POSITION_CHANNELS for c in sk.channels[j]):
            return j
        j = sk.parents[j]
    return 0


def _chain(sk: Skeleton, start: int, end: int) -> list[int]:
    """Joints from ``start`` down to ``end`` (``start`` must be an ancestor-or-self of ``end``)."""
    path = [end]
    while path[-1] != start:
        path.append(sk.parents[path[-1]])
    return path[::-1]


def _guess_notes(sk, notes, root, top, pelvis, head, toes, limbs, skipped, posture) -> list[str]:
    """What :func:`guess_spec` guessed and how, one line each."""
    n = sk.names
    out = ["guessed from joint names and the hierarchy: " + "; ".join(
        f"{key} {n[a]}/{n[b]}" for key, (a, b) in limbs.items() if (a, b) != (None, None))]
    out += notes
    out.append("knees and elbows found by name unless said otherwise; hips and shoulders are the joints "
               "above them (shoulder = glenohumeral joint, not the clavicle), feet and hands the ones below, "
               "each the joint that starts the next segment")
    if skipped:
        out.append(f"twist/roll/helper bones passed over (no role): {', '.join(n[j] for j in skipped)}")
    out.append(f"root {n[root]}: " + ("the joint where legs and arms branch" if root == top
                                      else f"nearest animated ancestor of {n[top]}, where legs and arms branch"))
    out.append(f"pelvis {n[pelvis]}: the first joint from {n[top]} toward the shoulders")
    out.append(f"head {n[head]}" if head is not None else "no head joint found; the spine ends where the arms branch")
    if None in toes:
        out.append("no toe joints found")
    out.append(posture)
    out.append("units unknown; up axis assumed y")
    return out


def _posture(sk: Skeleton, up: int, pelvis: int, chest: int, head: int | None, hips, feet,
             shoulders) -> tuple[str | None, str]:
    """Whether the rest pose is a humanoid's, standing upright: ``(problem, note)``, ``problem``
    ``None`` when it is (or when the rest pose cannot tell), else why not (see :func:`guess_spec`)."""
    axis = "xyz"[up]
    pos, ends = sk.rest_positions()
    height = pos[:, up]
    leg = [sum(float(sk.offsets[k].norm()) for k in _chain(sk, h, f)[1:]) for h, f in zip(hips, feet)]
    drop = [float(height[h] - height[f]) for h, f in zip(hips, feet)]
    if min(leg) <= 0 or any(d < _LEGS_HANG * length for d, length in zip(drop, leg)):
        return None, f"the rest pose does not show the legs hanging down along {axis}: quadruped check skipped"

    def lowest(j):
        inside = set(sk.descendants(j))
        tips = [float(ends[e, up]) for e, p in enumerate(sk.end_site_parents) if p in inside]
        return min([float(height[k]) for k in inside] + tips)

    ground = min(lowest(h) for h in hips)
    stand = min(float(height[h]) for h in hips) - ground
    gaps = [lowest(s) - ground for s in shoulders]
    four = all(gap <= _REACH * stand for gap in gaps)
    n = sk.names
    top = chest if chest != pelvis else head
    spine = None
    if top is not None and float((pos[top] - pos[pelvis]).norm()) > 0.05 * stand:
        v = pos[top] - pos[pelvis]
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(v[up] / v.norm())))))
        spine = (tilt, f"the spine ({n[pelvis]} to {n[top]}) is {tilt:.0f} degrees off the up axis {axis}")
    level = spine is not None and spine[0] > _UPRIGHT
    if four or level:
        reasons = [f"4 limbs reach the ground in the rest pose (the arms {n[shoulders[0]]}, "
                   f"{n[shoulders[1]]} too)"] if four else []
        reasons += [spine[1]] if level else []
        what = "it looks like a quadruped" if four else "it does not stand upright like a humanoid"
        return f"{what}: {'; '.join(reasons)}", ""
    return None, (f"rest pose upright: {spine[1] if spine else 'legs hanging down'}; the arms end "
                  f"{min(gaps) / stand:.0%} of the hip height above the feet")


def detect_spec(skeleton: Skeleton, filename=None) -> DatasetSpec:
    """The spec for a file: the first shipped spec whose ``files`` globs match ``filename``
    and that binds to ``skeleton``, else the first shipped spec that binds, else
    :func:`guess_spec` (the generic spec is never tried as a shipped spec)."""
    specs = [load_spec(n) for n in list_specs() if n != GENERIC]
    specs = [s for s in specs if not s.guess]
    if filename is not None:
        for spec in specs:
            if spec.matches_file(filename) and spec.binds(skeleton):
                return spec
    for spec in specs:
        if spec.binds(skeleton):
            return spec
    return guess_spec(skeleton)


# --------------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------------
def _clip_stem(name: str) -> str:
    """A clip name from a stem, file name or path (``.bvh`` dropped)."""
    base = PurePath(str(name)).name
    return base[:-4] if base.lower().endswith(".bvh") else base


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line."""
    return " ".join(str(exc).split())


def _kind_name(kind: type) -> str:
    """How messages name an expected TOML type."""
    return {str: "a string", list: "a list", dict: "a table", bool: "true or false"}.get(kind, kind.__name__)


def _describe(value) -> str:
    """A short ``type value`` description of a wrong value."""
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"
