"""Batching :class:`~torchsplice.data.MotionDataset` items: :func:`collate_motion` pads them to the
longest and stacks them (the ``collate_fn`` of a ``DataLoader``)."""

from __future__ import annotations

from typing import Any, Sequence

import torch

from .errors import DatasetError

__all__ = ["collate_motion"]


def collate_motion(items: Sequence[dict]) -> dict:
    """Pad items of :class:`MotionDataset` to the longest and stack them into a batch.

    Per-frame tensors (those whose first dimension is the item's ``length``: every feature)
    become ``(B, T, ...)`` with ``T`` the longest length; shorter items are padded by
    repeating their last frame. Other tensors are stacked as ``(B, ...)``.

    Returns a dict with the stacked features (on the items' device) and:

    - ``lengths``: ``(B,)`` int64 real frames per item; ``mask``: ``(B, T)`` bool, True on real
      frames (both on the features' device);
    - ``fps``: ``(B,)`` float64;
    - ``name``, ``index``, ``start``, ``skeleton``: lists (and any other non-tensor key as a list,
      e.g. ``labels``: a list of dicts).

    Raises :class:`DatasetError` (a ``ValueError``), one line naming two of the clips, when a
    feature's per-frame shape differs between items (clips on skeletons with other joints: see
    :meth:`MotionDataset.batch_sampler`).
    """
    items = list(items)
    if not items:
        raise ValueError("collate_motion needs at least one item")
    lengths = torch.tensor([int(it["length"]) for it in items], dtype=torch.int64)
    T = int(lengths.max())
    B = len(items)
    out: dict[str, Any] = {}
    device = next((v.device for v in items[0].values() if isinstance(v, torch.Tensor) and v.dim() >= 1), None)
    for key in items[0]:
        if key in ("length", "lengths", "mask"):
            continue
        values = [it[key] for it in items]
        if key == "fps":
            out[key] = torch.tensor([float(v) for v in values], dtype=torch.float64)
        elif not isinstance(values[0], torch.Tensor):
            out[key] = values
        elif values[0].dim() >= 1 and values[0].shape[0] == int(lengths[0]):
            shape = values[0].shape[1:]
            for it, v in zip(items, values):
                if v.shape != (int(it["length"]), *shape):
                    other = (f"skeleton {it['skeleton']} against {items[0]['skeleton']}: "
                             if "skeleton" in it and it["skeleton"] != items[0].get("skeleton") else "")
                    raise DatasetError(
                        f"cannot batch {key!r}: clip {it.get('name', '?')!r} has shape {tuple(v.shape)}, clip "
                        f"{items[0].get('name', '?')!r} (T, {', '.join(map(str, shape))}) ({other}clips on skeletons of "
                        "other joints); batch them with DataLoader(ds, batch_sampler=ds.batch_sampler(B), "
                        "collate_fn=collate_motion), or filter with where={'skeleton': K}")
            x = torch.empty((B, T, *shape), dtype=values[0].dtype, device=values[0].device)
            for b, v in enumerate(values):
                n = v.shape[0]
                x[b, :n] = v
                if 0 < n < T:
                    x[b, n:] = v[n - 1]
                elif n == 0:
                    x[b].zero_()
            out[key] = x
        else:
            try:
                out[key] = torch.stack(values)
            except RuntimeError as exc:
                raise ValueError(f"cannot batch {key!r}: {exc}") from None
    out["lengths"] = lengths.to(device) if device is not None else lengths
    out["mask"] = torch.arange(T, device=out["lengths"].device)[None, :] < out["lengths"][:, None]
    return out
