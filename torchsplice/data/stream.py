"""Streaming training batches from a motion database, without per-clip files.

:class:`ChunkedStream` is a ``torch.utils.data.IterableDataset`` of *batches*: an epoch's order
is the units (clips, windows, or a format's items) cut into chunks of consecutive rows, the
chunks shuffled, then the units shuffled within a few chunks at a time, so that each batch
reads a few nearby runs of the file (one HDF5 chunk serves many clips) and the order is still
well mixed. The order is a function of ``(seed, epoch)`` alone. With ``DataLoader(stream,
batch_size=None, num_workers=W)`` worker ``w`` computes batches ``w, w + W, ...`` of that order
(reading and assembling its clips itself: an alignment store's clips are assembled in the
workers), and the loader hands them over in order, so the batches are the same whatever ``W``.

Resuming mid-epoch: every batch carries ``batch["batch"]``, its number in the epoch;
:meth:`ChunkedStream.state_at` gives the state after it (``{"seed", "epoch", "next_batch"}``)
and :meth:`~ChunkedStream.load_state_dict` makes the next iteration start there, with the same
batches an uninterrupted epoch would have given. (Iterated in the training process itself,
:meth:`~ChunkedStream.state_dict` tracks the batches given out; a finished pass leaves the stream
at the start of its epoch. Call :meth:`~ChunkedStream.set_epoch` for the next epoch's order.)

:class:`MotionStream` streams :class:`~torchsplice.data.MotionDataset` items (any of its
features: ``rotations_6d``, ``velocities``, ``positions`` ...), collated by
:func:`~torchsplice.data.collate_motion`; ``torchsplice.formats.humanml3d_stream`` streams
HumanML3D's 263 features with captions.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from torch.utils.data import IterableDataset, get_worker_info

from ..core.errors import TorchspliceError
from .dataset import MotionDataset

__all__ = ["ChunkedStream", "MotionStream", "epoch_order"]


def epoch_order(units: int, chunk: int, shuffle_chunks: int, seed: int, epoch: int) -> np.ndarray:
    """The units ``0 .. units - 1`` in the order of epoch ``epoch``: chunks of ``chunk``
    consecutive units shuffled, then the units shuffled within each run of ``shuffle_chunks``
    chunks (a function of ``(seed, epoch)`` alone)."""
    rng = np.random.default_rng([int(seed), int(epoch)])
    chunks = [np.arange(s, min(s + chunk, units)) for s in range(0, units, chunk)]
    order = [chunks[i] for i in rng.permutation(len(chunks))]
    out = []
    for s in range(0, len(order), shuffle_chunks):
        run = np.concatenate(order[s:s + shuffle_chunks])
        out.append(run[rng.permutation(len(run))])
    return np.concatenate(out) if out else np.zeros(0, np.int64)


class ChunkedStream(IterableDataset):
    """Batches of ``batch_size`` units in a chunk-shuffled order (see the module docstring).

    A subclass gives the number of units (:meth:`_units`), optionally a group per unit that
    batches do not mix (:meth:`_groups`, e.g. the skeleton topology), and a batch's contents
    (:meth:`_batch`).
    """

    def __init__(self, batch_size: int = 32, chunk: int = 256, shuffle_chunks: int = 8, seed: int = 0,
                 drop_last: bool = False):
        for name, v in (("batch_size", batch_size), ("chunk", chunk), ("shuffle_chunks", shuffle_chunks)):
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise TorchspliceError(f"{{{name}}} must be a whole number of at least 1, got {v!r}", options=(name,))
        self.batch_size, self.chunk, self.shuffle_chunks = batch_size, chunk, shuffle_chunks
        self.seed, self.drop_last = int(seed), bool(drop_last)
        self.epoch, self.next_batch = 0, 0

    # -- what a subclass gives ----------------------------------------------------------------
    def _units(self) -> int:
        raise NotImplementedError

    def _groups(self) -> np.ndarray | None:
        return None

    def _batch(self, units: list[int]) -> dict:
        raise NotImplementedError

    # -- the order ----------------------------------------------------------------------------
    def batches(self, epoch: int | None = None) -> list[list[int]]:
        """The units of every batch of epoch ``epoch`` (default: the current one), in order."""
        epoch = self.epoch if epoch is None else epoch
        order = epoch_order(self._units(), self.chunk, self.shuffle_chunks, self.seed, epoch)
        groups = self._groups()
        keys = [None] if groups is None else list(dict.fromkeys(groups[order].tolist()))
        out: list[tuple[int, list[int]]] = []
        for key in keys:
            pos = np.arange(len(order)) if key is None else np.flatnonzero(groups[order] == key)
            for s in range(0, len(pos), self.batch_size):
                part = pos[s:s + self.batch_size]
                if len(part) < self.batch_size and self.drop_last:
                    continue
                out.append((int(part[0]), order[part].tolist()))
        return [units for _, units in sorted(out, key=lambda x: x[0])]

    def __len__(self) -> int:
        return len(self.batches())

    def set_epoch(self, epoch: int) -> None:
        """Start epoch ``epoch`` at its first batch (its order is new, and the same every time)."""
        self.epoch, self.next_batch = int(epoch), 0

    # -- resuming -----------------------------------------------------------------------------
    def state_dict(self) -> dict:
        """Where this stream stands: ``{"seed", "epoch", "next_batch"}`` (see the module docstring)."""
        return {"seed": self.seed, "epoch": self.epoch, "next_batch": self.next_batch}

    def state_at(self, batch: dict) -> dict:
        """The state right after ``batch`` (one this stream gave), for a checkpoint."""
        return {"seed": self.seed, "epoch": int(batch["epoch"]), "next_batch": int(batch["batch"]) + 1}

    def load_state_dict(self, state: dict) -> None:
        """Resume at ``state`` (from :meth:`state_dict` or :meth:`state_at`)."""
        if int(state["seed"]) != self.seed:
            raise TorchspliceError(f"this stream's seed is {self.seed}, the state's {state['seed']}: the batches would "
                                   "differ; make the stream with the seed it was saved with")
        self.epoch, self.next_batch = int(state["epoch"]), int(state["next_batch"])

    # -- iterating ----------------------------------------------------------------------------
    def __iter__(self):
        batches = self.batches()
        info = get_worker_info()
        first = self.next_batch
        if info is None:
            mine = range(first, len(batches))
        else:
            mine = range(first + info.id, len(batches), info.num_workers)
        for b in mine:
            out = self._batch(batches[b])
            out["batch"], out["epoch"] = b, self.epoch
            if info is None:
                self.next_batch = b + 1
            yield out
        if info is None:  # a finished pass leaves the stream at the start of its epoch (set_epoch moves on)
            self.next_batch = 0


class MotionStream(ChunkedStream):
    """:class:`~torchsplice.data.MotionDataset` items streamed in batches (see the module docstring).

    ``path`` and the keyword arguments ``features``, ``window``, ``stride``, ``select``, ``where``,
    ``split``, ``split_ratios``, ``split_seed``, ``dtype`` and ``assemble_on`` are
    :class:`MotionDataset`'s; a batch is :func:`~torchsplice.data.collate_motion` of its items
    (``mask``, ``lengths``, each feature padded; made on ``assemble_on`` where given, see
    :meth:`MotionDataset.collate`), plus ``batch`` and ``epoch``. Batches never mix skeletons of different topologies.
    """

    def __init__(self, path, batch_size: int = 32, *, features: Sequence[str] = ("rotations_6d", "velocities"),
                 chunk: int = 256, shuffle_chunks: int = 8, seed: int = 0, drop_last: bool = False, **dataset):
        super().__init__(batch_size, chunk, shuffle_chunks, seed, drop_last)
        self.dataset = MotionDataset(path, features=tuple(features), **dataset)

    def _units(self) -> int:
        return len(self.dataset)

    def _groups(self) -> np.ndarray | None:
        return self.dataset.item_topologies()

    def _batch(self, units: list[int]) -> dict:
        return self.dataset.collate(self.dataset.__getitems__(units))
