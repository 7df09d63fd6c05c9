"""Reading a dataset spec's tables (a TOML file, or the JSON stored in databases) into the
fields of a :class:`~torchsplice.specs.DatasetSpec`, each problem one
:class:`~torchsplice.core.errors.SpecError` line naming the file and key. Nothing here makes
a spec: :mod:`.spec` and :mod:`.loading` do, from these fields.
"""

from __future__ import annotations

import re
from pathlib import Path

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from ..core.errors import SpecError
from .clips import RoleRule
from .text import parse_phrase_table
from .vocabulary import AXES, GUESS_KEYS, GUESS_SINGLE, OPTIONAL_PAIRS, PAIRS, ROLES, SECTION_KEYS, UNITS, one_line

__all__ = ["spec_fields", "toml_fields"]


def toml_fields(text: str, path: Path) -> dict:
    """The fields of the spec file ``path`` holding ``text`` (see :func:`spec_fields`); its
    ``[dataset] name`` must be the file's stem."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML: {one_line(exc)}") from None
    fields = spec_fields(data, str(path), path=path)
    if fields["name"] != path.stem:
        raise SpecError(f"{path}: [dataset] name {fields['name']!r} must equal the file's stem {path.stem!r}")
    return fields


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


def spec_fields(data: dict, where: str, path: Path | None = None, from_json: bool = False) -> dict:
    """Validate the tables of a spec file (or its JSON form, ``from_json``) into the fields of a
    :class:`~torchsplice.specs.DatasetSpec` (its keyword arguments); ``where`` names the file
    in messages."""
    allowed = {"dataset", "joints", "clips", "text"} | ({"name", "path", "notes", "guessed"} if from_json else set())
    extra = sorted(set(data) - allowed)
    if extra:
        raise SpecError(f"{where}: unknown top-level key or table [{extra[0]}] (allowed: dataset, joints, clips, text)")
    dataset = _section(data, where, "dataset", required=True)
    joints = _section(data, where, "joints", required=True)
    clips = _section(data, where, "clips", required=False)
    fields_ = {**_parse_dataset(dataset), **_parse_joints(joints), **_parse_clips(clips)}
    if "text" in data:  # the phrase table, for captions: checked here, read by specs.text when captions are made
        parse_phrase_table(data["text"], where, fields_["name"])
    notes: tuple[str, ...] = ()
    guessed: tuple[tuple[str, tuple[str, ...]], ...] = ()
    if from_json:
        path, notes = _json_extras(data, where, fields_["name"])
        guessed = _json_guessed(data.get("guessed"), where)
    return {**fields_, "path": path, "notes": notes, "guessed": guessed}


def _section(data: dict, where: str, name: str, required: bool) -> _Table:
    """The table ``[name]`` with its keys checked."""
    value = data.get(name, {} if not required else None)
    if value is None:
        raise SpecError(f"{where}: missing table [{name}]")
    if not isinstance(value, dict):
        raise SpecError(f"{where}: [{name}] must be a table, got {_describe(value)}")
    table = _Table(value, where, name)
    table.check_keys(SECTION_KEYS[name])
    return table


def _parse_dataset(t: _Table) -> dict:
    """Fields of ``[dataset]``."""
    return {
        "name": t.get("name", str, required=True),
        "description": t.get("description", str, default="", empty=True),
        "up_axis": t.choice("up_axis", tuple(AXES), default="y"),
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
    out = {
        "root": t.get("root", str, required=True),
        "pelvis": t.get("pelvis", str, required=True),
        "spine": t.names("spine", required=True),
        "head": t.get("head", str),
        "upper_body": t.names("upper_body"),
        "lower_body": t.names("lower_body"),
    }
    out.update({k: t.pair(k, required=True) for k in PAIRS})
    out.update({k: t.pair(k) for k in OPTIONAL_PAIRS})
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
            raise t.fail("reference", 'must be a table of label = "value or {label} template" strings')
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
        raise t.fail(
            "ground_truth", "must hold a non-empty 'capture' table and optional 'action', 'locomotion' and 'same'"
        )
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
    return RoleRule(role, t.names("names") or (), tuple((k, lt.names(k, required=True) or ()) for k in sorted(labels)))


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
    extra = sorted(set(value) - set(GUESS_KEYS))
    if extra:
        raise SpecError(f"{where}: guessed: unknown key {extra[0]!r} (allowed: {', '.join(GUESS_KEYS)})")
    out = []
    for key in GUESS_KEYS:
        if key not in value:
            continue
        v = value[key]
        if key in GUESS_SINGLE:
            if not (v is None or (isinstance(v, str) and v)) or (v is None and key != "head"):
                raise SpecError(f"{where}: guessed: {key}: expected a joint name, got {_describe(v)}")
            out.append((key, () if v is None else (v,)))
        else:
            if not isinstance(v, list) or not all(isinstance(n, str) and n for n in v):
                raise SpecError(f"{where}: guessed: {key}: expected a list of joint names, got {_describe(v)}")
            out.append((key, tuple(v)))
    return tuple(out)


def _kind_name(kind: type) -> str:
    """How messages name an expected TOML type."""
    return {str: "a string", list: "a list", dict: "a table", bool: "true or false"}.get(kind, kind.__name__)


def _describe(value) -> str:
    """A short ``type value`` description of a wrong value."""
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"
