"""Training data: motion databases as PyTorch datasets (see :mod:`torchsplice.data.dataset`).

``MotionDataset(path, clips=None, where=None, window=None, stride=None, features=..., select=None)`` serves
clips or fixed-length windows of any torchsplice motion database as dicts of tensors
(quaternions WXYZ, positions in file units); ``collate_motion`` pads them into batches with
``lengths`` and ``mask``; ``ds.batch_sampler(B)`` batches a database of several skeletons one
topology at a time (:class:`SkeletonBatchSampler`).
"""

from .dataset import DatasetError, MotionDataset, collate_motion
from .sampler import SkeletonBatchSampler

__all__ = ["MotionDataset", "collate_motion", "DatasetError", "SkeletonBatchSampler"]
