"""Training data: motion databases as PyTorch datasets (see :mod:`torchsplice.data.dataset`).

``MotionDataset(path, clips=None, where=None, window=None, stride=None, features=..., select=None,
split=None)`` serves clips or fixed-length windows of any torchsplice motion database as dicts of
tensors (quaternions WXYZ, positions in file units); ``collate_motion`` pads them into batches
with ``lengths`` and ``mask``; ``ds.batch_sampler(B)`` batches a database of several skeletons one
topology at a time (:class:`SkeletonBatchSampler`); :mod:`.splits` splits clips by source clip;
``MotionStream`` streams batches in chunk-shuffled order, resumable mid-epoch (:mod:`.stream`).

The names below are imported on first use, so that :mod:`.splits` (which the exports and the
command line read) loads without torch.
"""

__all__ = ["MotionDataset", "collate_motion", "DatasetError", "SkeletonBatchSampler", "MotionStream", "ChunkedStream"]

from ..core.lazy import lazy_names

__getattr__, __dir__ = lazy_names(__name__, {
    "MotionDataset": ".dataset", "collate_motion": ".collate", "DatasetError": ".errors",
    "SkeletonBatchSampler": ".sampler", "MotionStream": ".stream", "ChunkedStream": ".stream"})
