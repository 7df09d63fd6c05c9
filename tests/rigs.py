"""Rigs the tests build: a sample clip on a skeleton that is not a humanoid (no arms)."""

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
