"""Training data: motion databases as PyTorch datasets (see :mod:`torchsplice.data.dataset`).

``MotionDataset(path, clips=None, where=None, window=None, stride=None, features=..., select=None)`` serves
clips or fixed-length windows of any torchsplice motion database as dicts of tensors
(quaternions WXYZ, positions in file units); ``collate_motion`` pads them into batches with
``lengths`` and ``mask``.
"""

from .dataset import DatasetError, MotionDataset, collate_motion

__all__ = ["MotionDataset", "collate_motion", "DatasetError"]
