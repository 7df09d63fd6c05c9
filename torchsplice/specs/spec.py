"""The dataset spec: :class:`DatasetSpec` (joint roles by name, axes, units, clip-naming rules).

Dataset specs: which joints of a dataset's skeleton play which role, and what its clips are.

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

Where no spec fits, :meth:`DatasetSpec.guess_for` (and :func:`guess_spec`, from the shipped
``generic`` spec) guesses one from common joint names and the hierarchy (:mod:`.guess`),
and :func:`detect_spec` picks a shipped spec for a file (or falls back on the guess). A guessed
spec says what it guessed: :meth:`DatasetSpec.guess_summary` (lines to print) and
:meth:`DatasetSpec.guessed_roles` (a JSON-able dict), kept through :meth:`DatasetSpec.to_json`.
Every problem is a one-line :class:`~torchsplice.core.errors.SpecError` naming the spec file.
"""

from __future__ import annotations

import fnmatch
import json
import re
from dataclasses import dataclass
from pathlib import Path, PurePath

from ..core.errors import SpecError
from ..core.skeleton import Skeleton
from .clips import RoleRule, clip_stem
from .guess import cannot_guess, guess_joints
from .parsing import spec_fields
from .roles import SkeletonRoles, bind_roles
from .vocabulary import GUESS_SINGLE, OPTIONAL_PAIRS, PAIRS, UNITS, one_line

__all__ = ["DatasetSpec"]


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
            return self.guess_for(skeleton).bind(skeleton)
        return bind_roles(self, skeleton)

    def resolve(self, skeleton: Skeleton) -> "DatasetSpec":
        """The spec with concrete joint names for ``skeleton``: itself, or for a ``guess``
        spec the guessed one (store this one, so that the guess is recorded)."""
        return self.guess_for(skeleton) if self.guess else self

    def guess_for(self, skeleton: Skeleton) -> "DatasetSpec":
        """A spec whose joints are guessed for ``skeleton`` (see :func:`~torchsplice.specs.guess_spec`),
        with this spec's name, description, up axis, units, files and clip rules; what was
        guessed is in its :attr:`guessed` record and ``notes``.

        Raises :class:`SpecError` saying what could not be guessed.
        """
        spec = DatasetSpec(
            name=self.name,
            description=self.description,
            up_axis=self.up_axis,
            units=self.units,
            files=self.files,
            pattern=self.pattern,
            default_role=self.default_role,
            rules=self.rules,
            path=None,
            **guess_joints(skeleton, self.up_axis),
        )
        try:
            spec.bind(skeleton)
        except SpecError as exc:
            raise cannot_guess(skeleton, f"the guess does not fit ({exc})") from None
        return spec

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
            out[key] = (names[0] if names else None) if key in GUESS_SINGLE else list(names)
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
        name = clip_stem(clip_name)
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
        return any(fnmatch.fnmatchcase(n, g) for g in self.files for n in (base, clip_stem(base)))

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
            raise SpecError(f"spec JSON: not valid JSON ({one_line(exc)})") from None
        if not isinstance(data, dict):
            raise SpecError("spec JSON: expected an object")
        path = data.get("path")
        where = f"spec JSON ({path})" if isinstance(path, str) else "spec JSON"
        return cls(**spec_fields(data, where, from_json=True))


def _to_dict(spec: DatasetSpec) -> dict:
    """See :meth:`DatasetSpec.to_dict`."""
    dataset = {
        "name": spec.name,
        "description": spec.description,
        "up_axis": spec.up_axis,
        "units": spec.units,
        **({"files": list(spec.files)} if spec.files else {}),
    }
    if spec.guess:
        joints = {"guess": True}
    else:
        keys = ("root", "pelvis", "spine", "head", "upper_body", "lower_body", *PAIRS, *OPTIONAL_PAIRS)
        joints = {k: getattr(spec, k) for k in keys if getattr(spec, k) is not None}
        joints = {k: list(v) if isinstance(v, tuple) else v for k, v in joints.items()}
    rules = [
        {
            "role": r.role,
            **({"names": list(r.names)} if r.names else {}),
            **({"labels": {k: list(v) for k, v in r.labels}} if r.labels else {}),
        }
        for r in spec.rules
    ]
    clips: dict[str, object] = {"default_role": spec.default_role, "role": rules}
    if spec.pattern is not None:
        clips["pattern"] = spec.pattern
    if spec.reference is not None:
        clips["reference"] = dict(spec.reference)
    if spec.ground_truth is not None:
        act, loco, cap, same = spec.ground_truth
        clips["ground_truth"] = {
            "action": dict(act),
            "locomotion": dict(loco),
            "capture": dict(cap),
            "same": list(same),
        }
    out = {"name": spec.name, "dataset": dataset, "joints": joints, "clips": clips, "notes": list(spec.notes)}
    if spec.path is not None:
        out["path"] = str(spec.path)
    if spec.guessed:
        out["guessed"] = spec.guessed_roles()
    return out
