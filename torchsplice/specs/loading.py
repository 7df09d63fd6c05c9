"""Which spec: the shipped ones (``torchsplice.datasets_spec``) and spec files by name or path
(:func:`load_spec`, :func:`list_specs`), a spec guessed for a skeleton (:func:`guess_spec`)
and the spec that fits a file (:func:`detect_spec`); each problem one
:class:`~torchsplice.core.errors.SpecError` line naming the file.
"""

from __future__ import annotations

import functools
import importlib.resources
from pathlib import Path, PurePath

from ..core.errors import SpecError
from ..core.skeleton import Skeleton
from .parsing import toml_fields
from .spec import DatasetSpec
from .vocabulary import GENERIC, SHIPPED_PACKAGE

__all__ = ["load_spec", "list_specs", "guess_spec", "detect_spec"]


def list_specs() -> list[str]:
    """Names of the shipped specs (the ``*.toml`` stems in ``torchsplice.datasets_spec``)."""
    root = importlib.resources.files(SHIPPED_PACKAGE)
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
    res = importlib.resources.files(SHIPPED_PACKAGE) / f"{name}.toml"
    return DatasetSpec(**toml_fields(res.read_text(encoding="utf-8"), Path(str(res))))


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
    return DatasetSpec(**toml_fields(text, path))


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
    return (base or load_spec(GENERIC)).guess_for(skeleton)


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
