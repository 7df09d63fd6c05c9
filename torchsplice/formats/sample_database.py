"""The built-in sample as a database: what ``torchsplice sample -o OUT`` writes, for a first run
with no data.

Every clip of :func:`torchsplice.sample.sample_motions` (float32, 30 fps, the standard 22-joint
sample skeleton, centimetres, Y up) appended with the ``sample`` dataset spec, so that the job
finds its locomotions and actions by their roles.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from ..sample import sample_motions
from ..specs import load_spec
from ..store.database import MotionDatabase

if TYPE_CHECKING:
    from ..core.motion import Motion

__all__ = ["write_sample"]


def write_sample(out: str | Path, *, overwrite: bool = False) -> list[Motion]:
    """Write the built-in sample database to ``out`` (.h5) and return its clips, in the order
    written. Refuses an existing ``out`` unless ``overwrite``
    (:class:`~torchsplice.core.errors.OutputExistsError`), and a file another process is
    writing (:class:`~torchsplice.store.lock.LockedError`); the file appears only once complete."""
    spec = load_spec("sample")
    motions = sample_motions()
    with MotionDatabase.create(out, overwrite=overwrite) as db:
        for m in motions:
            db.append(m, spec=spec)
    return motions
