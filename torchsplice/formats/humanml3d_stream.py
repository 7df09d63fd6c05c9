"""HumanML3D's features and captions streamed from a database, without per-clip files.

:class:`HumanML3DStream` is the ``humanml3d`` export (:mod:`.humanml3d_exporter`) as a
``torch.utils.data.IterableDataset`` of batches: the same items (clips on the SMPL body at 20
fps, windows, mirrors), the same 263 features computed by the same code, the same captions and
the same leakage-free splits by source clip, in the chunk-shuffled, resumable order of
:class:`~torchsplice.data.stream.ChunkedStream`. A training loop (T2M-GPT, MoMask, MDM style)::

    from torch.utils.data import DataLoader
    from torchsplice.formats.humanml3d_stream import HumanML3DStream

    stream = HumanML3DStream("spliced.h5", batch_size=64, split="train", window=6.0)
    for batch in DataLoader(stream, batch_size=None, num_workers=2):
        x = batch["motion"]          # (B, N, 263) float32, padded with zeros
        n = batch["lengths"]         # (B,) rows of each motion
        text = batch["caption"]      # B sentences, one of each motion's captions
        state = stream.state_at(batch)   # save it: stream.load_state_dict(state) resumes after it

A batch: ``motion`` ``(B, N, 263)``, ``lengths``, ``mask`` ``(B, N)``, ``caption`` (one
caption per motion, chosen by the stream's seed, epoch and the motion's id), ``captions`` (every
caption line of each motion, as its ``texts/ID.txt``), ``id``, ``clip``, ``split``,
``batch``, ``epoch``. ``normalize=(mean, std)`` (the export's ``Mean.npy``/``Std.npy``, or
:meth:`HumanML3DStream.statistics`) gives ``(x - mean) / std`` instead.
"""

from __future__ import annotations

import os
import zlib
from functools import cached_property

import numpy as np
import torch

from ..core.errors import TorchspliceError
from ..data.splits import DEFAULT_RATIOS, SPLITS
from ..data.stream import ChunkedStream
from ..store.database import MotionDatabase
from .humanml3d_exporter import HumanML3DExporter
from .humanml3d_features import FeatureStats

__all__ = ["HumanML3DStream"]


class HumanML3DStream(ChunkedStream):
    """Batches of HumanML3D features and captions (see the module docstring).

    Args:
        path: the database (a motion or an alignment store).
        clips: the clips (names or selectors, as ``export``); ``None``: every clip.
        split: ``"train"``, ``"val"``, ``"test"`` or ``None`` (every motion).
        captions, mirror, window, split_ratios, split_seed, paraphrases: the ``humanml3d``
            export's options, with its defaults.
        normalize: ``None``, or ``(mean, std)`` arrays of 263 values.
        batch_size, chunk, shuffle_chunks, seed, drop_last: see :class:`ChunkedStream`.
    """

    def __init__(self, path, batch_size: int = 32, *, clips=None, split: str | None = None, captions=None,
                 mirror: bool = False, window: float | None = None, split_ratios=DEFAULT_RATIOS, split_seed: int = 0,
                 paraphrases: int = 3, normalize=None, chunk: int = 256, shuffle_chunks: int = 8, seed: int = 0,
                 drop_last: bool = False):
        super().__init__(batch_size, chunk, shuffle_chunks, seed, drop_last)
        if split is not None and split not in SPLITS:
            raise TorchspliceError(f"{{split}} must be one of {', '.join(SPLITS)} or None, got {split!r}", options=("split",))
        self.path, self.split = path, split
        self.exporter = HumanML3DExporter(path, clips, captions=captions, mirror=mirror, window=window,
                                          split_ratios=split_ratios, split_seed=split_seed, paraphrases=paraphrases)
        self.exporter.check()  # the plan, the captions and the map onto the SMPL body, before any batch
        items = self.exporter.planned_items
        self.items = [it for it in items if split is None or it["split"] == split]
        if not self.items:
            raise TorchspliceError(f"{path}: no motion in the {split} split")
        self.normalize = None if normalize is None else tuple(torch.as_tensor(np.asarray(a), dtype=torch.float32)
                                                              for a in normalize)
        self._db, self._pid = None, None

    def __getstate__(self):  # workers open the database themselves
        return {**self.__dict__, "_db": None, "_pid": None}

    def _units(self) -> int:
        return len(self.items)

    def _database(self):
        if self._db is None or self._pid != os.getpid():  # a forked worker opens its own
            self._db, self._pid = MotionDatabase.open(self.path), os.getpid()
        return self._db

    def _features(self, units: list[int]) -> dict[str, tuple]:
        """``id -> (item, features, captions)`` of the items ``units``."""
        chosen = [self.items[u] for u in units]
        return {item["id"]: (item, feats, caps) for item, feats, _, caps in
                self.exporter.motions(chosen, self._database())}

    def _batch(self, units: list[int]) -> dict:
        done = self._features(units)
        ids = [self.items[u]["id"] for u in units]
        feats = [done[i][1].to(torch.float32) for i in ids]
        lengths = torch.tensor([f.shape[0] for f in feats], dtype=torch.int64)
        motion = torch.zeros((len(feats), int(lengths.max()), feats[0].shape[1]), dtype=torch.float32)
        for b, f in enumerate(feats):
            motion[b, :f.shape[0]] = f if self.normalize is None else (f - self.normalize[0]) / self.normalize[1]
        lines = [[c.line() for c in done[i][2]] for i in ids]
        pick = [int(np.random.default_rng([self.seed, self.epoch, zlib.crc32(i.encode())]).integers(len(c)))
                for i, c in zip(ids, lines)]
        return {"motion": motion, "lengths": lengths,
                "mask": torch.arange(motion.shape[1])[None, :] < lengths[:, None],
                "caption": [done[i][2][p].text for i, p in zip(ids, pick)], "captions": lines, "id": ids,
                "clip": [done[i][0]["clip"] for i in ids], "split": [done[i][0]["split"] for i in ids]}

    @cached_property
    def statistics(self) -> tuple[np.ndarray, np.ndarray]:
        """``(mean, std)`` of the stream's motions as the export computes ``Mean.npy`` and
        ``Std.npy`` (one pass over every motion of the split)."""
        stats = FeatureStats()
        for _, feats, _, _ in self.exporter.motions(self.items, self._database()):
            stats.add(feats)
        mean, std = stats.result()
        return mean.numpy().astype(np.float32), std.numpy().astype(np.float32)
