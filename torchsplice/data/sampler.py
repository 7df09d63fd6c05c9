"""Batches of one skeleton topology, for a :class:`~torchsplice.data.MotionDataset` whose clips
are on several (a mixed database): :meth:`MotionDataset.batch_sampler
<torchsplice.data.MotionDataset.batch_sampler>` makes one."""

from __future__ import annotations

import random

__all__ = ["SkeletonBatchSampler"]


class SkeletonBatchSampler:
    """Batches of item indices, each batch from one group (the items of one skeleton topology:
    :meth:`MotionDataset.batch_sampler`). Without ``shuffle``, group by group in order; with it,
    each epoch (each iteration) shuffles the items within each group and the order of the batches,
    from ``seed`` and the epoch's number, so runs repeat. ``drop_last`` drops each group's last
    batch when it is short."""

    def __init__(self, groups: list[list[int]], batch_size: int, shuffle: bool = False, seed: int = 0,
                 drop_last: bool = False):
        if not isinstance(batch_size, int) or isinstance(batch_size, bool) or batch_size < 1:
            raise ValueError(f"batch_size must be a whole number of at least 1, got {batch_size!r}")
        self.groups, self.batch_size, self.shuffle, self.seed, self.drop_last = groups, batch_size, shuffle, seed, drop_last
        self.epoch = 0

    def _batches(self, rng) -> list[list[int]]:
        out = []
        for group in self.groups:
            order = list(group)
            if rng is not None:
                rng.shuffle(order)
            for b in range(0, len(order), self.batch_size):
                batch = order[b:b + self.batch_size]
                if len(batch) == self.batch_size or not self.drop_last:
                    out.append(batch)
        if rng is not None:
            rng.shuffle(out)
        return out

    def __iter__(self):
        rng = random.Random(f"{self.seed}:{self.epoch}") if self.shuffle else None
        self.epoch += 1
        return iter(self._batches(rng))

    def __len__(self) -> int:
        full = sum(len(g) // self.batch_size for g in self.groups)
        return full if self.drop_last else full + sum(1 for g in self.groups if len(g) % self.batch_size)
