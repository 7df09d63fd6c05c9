"""Rigs the tests build: a sample clip on a skeleton that is not a humanoid (no arms), and a clip
on its rig turned onto another up axis."""

from __future__ import annotations

from dataclasses import replace

from torchsplice.sample import sample_motions


def armless_sample():
    """The sample's first clip with its arms, hands and shoulders cut off (a skeleton retargeting
    must refuse, naming the missing elbow)."""
    m = sample_motions()[0]
    sk = m.skeleton
    keep = [j for j in range(sk.num_joints) if not any(w in sk.names[j] for w in ("Arm", "Hand", "Shoulder"))]
    index = {j: n for n, j in enumerate(keep)}
    armless = replace(sk, names=tuple(sk.names[j] for j in keep),
                      parents=tuple(index[sk.parents[j]] if sk.parents[j] >= 0 else -1 for j in keep),
                      offsets=sk.offsets[keep], channels=tuple(sk.channels[j] for j in keep),
                      end_site_parents=tuple(index[p] for p in sk.end_site_parents if p in index),
                      end_site_offsets=sk.end_site_offsets[[e for e, p in enumerate(sk.end_site_parents) if p in index]])
    return replace(m, skeleton=armless, rotations=m.rotations[:, keep],
                   translations=None if m.translations is None else m.translations[:, keep])


def turned(motion, axis: str):
    """``motion`` on its skeleton turned from Y up onto up axis ``axis`` (``"x"``, ``"y"``,
    ``"z"``) by :func:`torchsplice.core.rotations.up_axis_turn`: the rest offsets, end sites,
    root path and joint translations turned, every local rotation conjugated, so that the clip
    stands and moves along ``axis`` as a rig exported that way would (its world positions are
    the original's turned)."""
    from torchsplice.core.rotations import quat_apply, quat_conj, quat_mul, up_axis_turn
    from torchsplice.specs.vocabulary import AXES

    u = up_axis_turn(1, AXES[axis])
    sk = motion.skeleton
    skeleton = replace(sk, offsets=quat_apply(u.expand(sk.num_joints, 4), sk.offsets.double()),
                       end_site_offsets=quat_apply(u.expand(len(sk.end_site_offsets), 4), sk.end_site_offsets.double()))
    rot = motion.rotations.double()
    rot = quat_mul(quat_mul(u.expand_as(rot), rot), quat_conj(u).expand_as(rot))
    root = quat_apply(u.expand(motion.num_frames, 4), motion.root_translation.double())
    trans = None if motion.translations is None else quat_apply(u.expand(*motion.translations.shape[:-1], 4),
                                                                motion.translations.double())
    dtype = motion.rotations.dtype
    return replace(motion, skeleton=skeleton, rotations=rot.to(dtype), root_translation=root.to(dtype),
                   translations=None if trans is None else trans.to(dtype))
