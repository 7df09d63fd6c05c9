"""What :class:`~torchsplice.store.database.MotionDatabase` holds, declared once for its mixins
(:class:`~torchsplice.store.reading.Reading`, :class:`~torchsplice.store.writing.Writing`,
:class:`~torchsplice.store.assembling.Assembling`): :class:`DatabaseState`.

The mixins read and write the database's state and call one another's methods; the state is
set by ``MotionDatabase.__init__`` (and by ``create``, ``open`` and ``resume``), the methods
are the mixins' own. :class:`DatabaseState` declares both for the type checker: its
attributes are annotations only and its methods exist only under ``TYPE_CHECKING``, so at
run time it adds nothing to the database (every name resolves as it would without it).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np

from ..core.motion import Motion
from ..core.skeleton import Skeleton
from .resumable import RowLog

if TYPE_CHECKING:
    from .frame_array import FrameArray
    from .lock import FileLock

__all__ = ["DatabaseState"]


class DatabaseState:
    """The state of :class:`~torchsplice.store.database.MotionDatabase` and the methods its
    mixins call across one another (see the module's docstring)."""

    path: Path
    _h5: h5py.File | None  # None once closed
    mode: str  # "r", "a" (an append, on a copy) or "w" (a new or resumed file)
    _tmp: Path | None  # the file a write works on (a copy, a temporary or the staging file)
    _target: Path  # the file a write replaces on close (an append through a link: its target)
    _dtype: np.dtype  # the dtype of the stored frames
    _lock: FileLock | None  # the writer's lock, released on close
    _skeletons: list[Skeleton]
    _names: list[str] | None  # the written clips' names, read once when first asked for
    _name_index: dict[str, int] | None  # name -> row, written and staged clips
    _info_reads: int  # clip_info calls answered from the file, column by column (see clip_info)
    _flushed: int  # clips written to the file
    _declared: dict[str, str]  # every declared clip column, the store's own parts too
    columns: dict[str, str]  # the declared clip columns but the store's own parts
    frame_columns: tuple[str, ...]
    _staged: list[tuple[Motion, int, dict, dict]]  # (clip, skeleton, extra, frame_extra) appended, not written
    _staged_frames: int
    _skeleton_ids: dict[int, tuple[Skeleton, int]]  # id -> (object kept alive, row)
    _virtual: dict[int, list[tuple[str, int]]]  # skeleton -> (source file, frames) in order
    _resumable: bool  # written at a staging path across runs (see checkpoint, resume)
    _row_log: RowLog | None  # a resumable database's clip-table rows until it closes
    _growing: dict[int, tuple[int, tuple[str, ...]]]  # skeleton -> (its group's members, its growing datasets)

    if TYPE_CHECKING:
        # MotionDatabase's own
        @property
        def h5(self) -> h5py.File: ...
        @property
        def attrs(self) -> dict: ...
        def __len__(self) -> int: ...
        def spec_json(self, skeleton: int) -> str: ...
        def abort(self, failed: bool = False) -> None: ...

        # Reading's
        def _index_map(self) -> dict[str, int]: ...
        def _table_written(self) -> None: ...

        # Writing's
        def flush(self) -> None: ...
        def _writable(self) -> None: ...
        def _reserve(self, nbytes: int) -> None: ...
        def add_skeleton(self, skeleton: Skeleton, spec: Any = None) -> int: ...
        def _new_names(self, names: list[str]) -> dict: ...
        def _rows(self, names, lengths, fps, sources, roles, labels, extra: dict) -> dict: ...
        def _append_rows(self, k: int, n0: int, lengths, names, fps, sources, roles, labels, extra: dict) -> None: ...
        def _store_rows(self, rows: dict) -> None: ...
        def _added(self, index: dict, names: list[str]) -> None: ...
        def _growing_datasets(self, k: int) -> dict[str, h5py.Dataset]: ...
        def _no_virtual(self, k: int) -> None: ...
        def _virtual_rows(self, k: int) -> int: ...
        def _virtual_source(self, source: Path, refer_as: Path | None) -> str: ...

        # Assembling's
        @property
        def store(self) -> str: ...
        def assembled(self, k: int, starts, lengths, names=None, threads: int = 1) -> dict[str, np.ndarray]: ...
        def assembled_on(self, k: int, starts, lengths, device, names=None) -> dict: ...
        def assembled_array(self, k: int, name: str) -> FrameArray: ...
        def whole_frames(self, k: int) -> dict[str, np.ndarray]: ...
