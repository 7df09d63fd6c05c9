"""Reading a HumanML3D folder: each motion as a clip on the SMPL body, its captions kept.

A HumanML3D folder (the format's own, or one :mod:`.humanml3d_exporter` wrote) holds
``new_joint_vecs/ID.npy`` (``(N, 263)`` features), ``texts/ID.txt`` and the split lists. Each
ID (those of ``all.txt`` in its order, then every other ``new_joint_vecs/*.npy``: a torchsplice
export lists a result in no split in no list) becomes a clip
named ``ID`` of ``N`` frames at 20 fps on the built-in SMPL body (:mod:`torchsplice.specs.smpl`,
metres, Y up, spec ``smpl22``; a mirrored copy, whose left and right bones have swapped lengths,
on its mirror image, ``smpl22_skeleton(mirrored=True)``, chosen by the bone lengths):

- the joint positions are the features' (:func:`~.humanml3d_features.features_to_positions`:
  the root integrated from its velocities, the joints from their root-relative positions);
- the local rotations come from those positions (:func:`positions_to_motion`): the pelvis and
  the chest by two directions each (across the hips or collars, and up the spine), every other
  joint by the swing taking its rest bone onto its bone, as the format's own rotations are
  (swing only: no twist about a bone); the root is the pelvis's position. On the format's
  standard bone lengths, forward kinematics gives the positions back (to the rounding of the
  lengths, 0.1 mm a bone);
- the captions are kept as the clip's ``captions`` label (one line each, as in the file), so
  that spliced results compose them (:mod:`.captions`); role ``both`` (any motion can give
  either body half), label ``split`` (``train``, ``val``, ``test``) where a list names it (an
  export keeps it: :mod:`.splits`), and ``mirror_of`` on a mirrored copy ``M``+ID whose
  original is in the folder (the two split together).

A motion that cannot be used (a file of the wrong width, NaN, fewer than 2 frames, a missing or
malformed text, an ID a list names without a motion) is skipped with one line naming its file;
the others land.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ..core.errors import TorchspliceError
from ..core.motion import Motion
from ..core.rotations import quat_between, quat_apply, quat_conj, quat_mul, rotmat_to_quat
from ..specs.smpl import SMPL22_PARENTS, smpl22_skeleton
from .bvh_limits import MAX_ABS_VALUE
from .captions import parse_caption_line
from .humanml3d_features import FEATURES, FPS, features_to_positions
from .plain_files import MAX_ARRAY_BYTES, checked_file, read_capped_text

__all__ = ["is_humanml3d_folder", "humanml3d_ids", "read_humanml3d_motion", "read_humanml3d_motions", "positions_to_motion",
           "positions_to_motions", "SPLIT_FILES"]

SPLIT_FILES = ("train", "val", "test")
_FRAMES = ((0, (1, 2), 3), (9, (13, 14), 12))  # (joint, (left, right), up): the pelvis and the chest


def is_humanml3d_folder(path) -> bool:
    """Whether ``path`` is a folder holding ``new_joint_vecs/``."""
    path = Path(path)
    return path.is_dir() and (path / "new_joint_vecs").is_dir()


def humanml3d_ids(folder) -> tuple[list[str], dict[str, str], list[tuple[str, str]]]:
    """``(ids, split of each id, skipped)``: the motions to read (``all.txt``'s in its order,
    then every other ``new_joint_vecs/*.npy``, sorted), the split lists' memberships, and
    ``(file, why)`` for an ID a list names without a motion."""
    folder = Path(folder)
    vecs = folder / "new_joint_vecs"
    present = {f.stem for f in vecs.glob("*.npy")}
    listed: dict[str, list[str]] = {}
    skipped: list[tuple[str, str]] = []
    for name in (*SPLIT_FILES, "all"):
        f = folder / f"{name}.txt"
        if f.exists() or f.is_symlink():
            try:
                text = read_capped_text(f, inside=folder)
            except TorchspliceError as exc:  # a list that cannot be read: said, the motions still land
                skipped.append((str(f), str(exc).removeprefix(f"{f}: ")))
                continue
            listed[name] = [ln.strip() for ln in text.splitlines() if ln.strip()]
    lists: dict[str, list[str]] = {}  # id -> the split lists naming it
    for s in SPLIT_FILES:
        for i in dict.fromkeys(listed.get(s, [])):
            lists.setdefault(i, []).append(s)
    split = {i: ls[0] for i, ls in lists.items() if len(ls) == 1}
    for name, ids in listed.items():
        for i in ids:
            if i not in present:
                skipped.append((str(folder / f"{name}.txt"), f"lists {i!r}, which has no motion (new_joint_vecs/{i}.npy)"))
    ids = [i for i in listed.get("all", []) if i in present]
    ids += sorted(present - set(ids))
    twice = {i: ls for i, ls in lists.items() if len(ls) > 1 and i in present}
    for i, ls in twice.items():  # which split it is in cannot be told: said, not guessed
        skipped.append((str(vecs / f"{i}.npy"), f"listed in {' and '.join(f'{s}.txt' for s in ls)}: in which split it is "
                                                 "cannot be told (list it in one)"))
    ids = [i for i in ids if i not in twice]
    return list(dict.fromkeys(ids)), split, skipped


def positions_to_motion(positions: torch.Tensor, name: str = "clip", fps: float = FPS) -> Motion:
    """A :class:`~torchsplice.core.motion.Motion` on the SMPL body from its joint positions
    ``(T, 22, 3)`` in metres (HumanML3D's joint order): see the module docstring. Float64."""
    return positions_to_motions([positions], [name], fps)[0]


def positions_to_motions(positions, names, fps: float = FPS) -> list[Motion]:
    """:func:`positions_to_motion` of each of ``positions`` (``(T_i, 22, 3)`` each, named by
    ``names``), computed together: the clips' frames are concatenated, so that the loops over
    joints run once for them all (the same numbers as one clip at a time)."""
    ps = [x.to(torch.float64) for x in positions]
    for x in ps:
        if x.dim() != 3 or x.shape[1:] != (22, 3):
            raise ValueError(f"positions must be (T, 22, 3), got {tuple(x.shape)}")
    if not ps:
        return []
    lengths = torch.tensor([x.shape[0] for x in ps])
    p = torch.cat(ps)
    T = p.shape[0]
    parents = torch.tensor(SMPL22_PARENTS[1:])
    clip_of = torch.repeat_interleave(torch.arange(len(ps)), lengths)
    # each clip's mean bone lengths choose its body: a mirrored copy stands on the mirrored one
    lengths_of = torch.zeros(len(ps), 21, dtype=torch.float64).index_add_(0, clip_of, (p[:, 1:] - p[:, parents]).norm(dim=-1))
    lengths_of = lengths_of / lengths.to(torch.float64)[:, None]
    bodies = [smpl22_skeleton(), smpl22_skeleton(mirrored=True)]
    misfit = torch.stack([((b.offsets[1:].norm(dim=-1) - lengths_of) ** 2).sum(-1) for b in bodies], dim=1)
    body_of = misfit.argmin(dim=1)  # the first where both fit alike
    rest = torch.stack([b.offsets for b in bodies])[body_of[clip_of]]  # (T, 22, 3)
    children: dict[int, list[int]] = {}
    for j, parent in enumerate(SMPL22_PARENTS):
        if parent >= 0:
            children.setdefault(parent, []).append(j)
    G = torch.zeros(T, 22, 4, dtype=torch.float64)
    G[..., 0] = 1.0
    framed = {j: (lr, up) for j, lr, up in _FRAMES}
    for j, parent in enumerate(SMPL22_PARENTS):  # the loop over joints, every frame of every clip at once
        if j in framed:
            (left, right), up = framed[j]
            G[:, j] = _two_directions(p[:, left] - p[:, right], p[:, up] - p[:, j],
                                      rest[:, left] - rest[:, right], rest[:, up])
        elif len(children.get(j, [])) == 1:
            c = children[j][0]
            bone = p[:, c] - p[:, j]
            bone = bone / bone.norm(dim=-1, keepdim=True).clamp_min(1e-12)
            at_rest = quat_apply(G[:, parent], rest[:, c] / rest[:, c].norm(dim=-1, keepdim=True))
            G[:, j] = quat_mul(quat_between(at_rest, bone), G[:, parent])
        else:  # an end (feet, head, wrists): as its parent
            G[:, j] = G[:, parent]
    local = G.clone()
    local[:, 1:] = quat_mul(quat_conj(G[:, parents]), G[:, 1:])
    return [Motion(skeleton=bodies[int(b)], rotations=r, root_translation=x[:, 0].clone(), fps=float(fps), name=n)
            for b, r, x, n in zip(body_of, local.split(lengths.tolist()), p.split(lengths.tolist()), names)]


def _two_directions(across: torch.Tensor, up: torch.Tensor, rest_across: torch.Tensor,
                    rest_up: torch.Tensor) -> torch.Tensor:
    """``(T, 4)`` the rotation taking the rest frame of (across, up) onto the frames ``(T, 3)``."""
    def frame(a, u):
        y = u / u.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        x = a - (a * y).sum(-1, keepdim=True) * y
        x = x / x.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        return torch.stack([x, y, torch.linalg.cross(x, y, dim=-1)], dim=-1)

    now = frame(across, up)
    then = frame(rest_across.expand_as(across), rest_up.expand_as(up))
    return rotmat_to_quat(now @ then.transpose(-1, -2))


def read_humanml3d_motion(folder, id: str, split: str | None = None) -> Motion:
    """The motion ``id`` of the HumanML3D ``folder`` as a clip (see the module docstring);
    :class:`~torchsplice.core.errors.TorchspliceError` naming the file for one that cannot be used."""
    got = read_humanml3d_motions([(folder, id, split)])[0]
    if isinstance(got, BaseException):
        raise got
    return got


def read_humanml3d_motions(items) -> list:
    """:func:`read_humanml3d_motion` of each ``(folder, id, split)`` of ``items``, the rotations of
    them all computed together (:func:`positions_to_motions`): per item its clip, or the
    :class:`~torchsplice.core.errors.TorchspliceError` that says why it cannot be used (or the
    error a bug met on it raised, so that the caller reports it with its file)."""
    out: list = []
    read = []
    for folder, id, split in items:
        try:
            positions, lines = _checked(Path(folder), id)
        except (KeyboardInterrupt, MemoryError):
            raise
        except Exception as exc:
            out.append(exc)
            continue
        out.append(None)
        read.append((len(out) - 1, Path(folder), id, split, positions, lines))
    motions = positions_to_motions([r[4] for r in read], [r[2] for r in read])
    for (k, folder, id, split, _, lines), m in zip(read, motions):
        m.role = "both"
        m.labels = {"captions": "\n".join(ln.strip() for ln in lines)}
        if split:
            m.labels["split"] = split
        if id.startswith("M") and (folder / "new_joint_vecs" / f"{id[1:]}.npy").is_file():
            m.labels["mirror_of"] = id[1:]  # one source with its original, for splits
        out[k] = m
    return out


def _checked(folder: Path, id: str) -> tuple[torch.Tensor, list[str]]:
    """The joint positions ``(N, 22, 3)`` of motion ``id`` and its caption lines, every check
    made (a :class:`~torchsplice.core.errors.TorchspliceError` naming the file)."""
    f = folder / "new_joint_vecs" / f"{id}.npy"
    checked_file(f, inside=folder, limit=MAX_ARRAY_BYTES)  # no FIFO, device or symlink out of the folder
    try:
        data = np.load(f, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise TorchspliceError(f"{f}: not a NumPy array file ({' '.join(str(exc).split())})") from None
    if not isinstance(data, np.ndarray):  # an .npz archive under an .npy name
        data.close()
        raise TorchspliceError(f"{f}: a NumPy .npz archive, not one array (.npy)")
    if data.ndim != 2 or data.shape[1] != FEATURES:
        raise TorchspliceError(f"{f}: expected (frames, {FEATURES}) features, got shape {tuple(data.shape)}")
    if data.shape[0] < 2:
        raise TorchspliceError(f"{f}: {data.shape[0]} frame(s); a clip needs at least 2")
    if not np.issubdtype(data.dtype, np.floating) or not np.isfinite(data).all():
        bad = int(np.argwhere(~np.isfinite(data))[0][0]) if np.issubdtype(data.dtype, np.floating) else 0
        raise TorchspliceError(f"{f}: not finite (NaN or infinity) at frame {bad}" if np.issubdtype(data.dtype, np.floating)
                               else f"{f}: features of type {data.dtype}, not floating point")
    huge = np.abs(data) > MAX_ABS_VALUE  # as BVH import refuses: no motion has such values
    if huge.any():
        raise TorchspliceError(f"{f}: an absurd value (beyond {MAX_ABS_VALUE:g}) at frame {int(np.argwhere(huge)[0][0])}")
    text = folder / "texts" / f"{id}.txt"
    if not (text.exists() or text.is_symlink()):
        raise TorchspliceError(f"{text}: missing (every motion has its captions in texts/ID.txt)")
    lines = [ln for ln in read_capped_text(text, inside=folder, limit=1 << 20).splitlines() if ln.strip()]
    if not lines:
        raise TorchspliceError(f"{text}: holds no caption")
    for k, line in enumerate(lines, 1):
        parse_caption_line(line, f"{text}: line {k}")
    positions = features_to_positions(torch.from_numpy(data.astype(np.float64)))
    far = ~torch.isfinite(positions) | (positions.abs() > MAX_ABS_VALUE)  # velocities summed past the limit
    if bool(far.any()):
        raise TorchspliceError(f"{f}: its root velocities integrate beyond {MAX_ABS_VALUE:g} by frame "
                               f"{int(far.nonzero()[0, 0])}")
    return positions, lines
