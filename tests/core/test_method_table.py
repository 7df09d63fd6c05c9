"""The built-in methods' table (torchsplice.core.method_table) is their one declaration: every
row is registered, has its own kernel code, and says what the method does as the API shows it."""

from __future__ import annotations

import math

import pytest
import torch

from torchsplice.core.method_table import BUILTINS, builtin, resolve
from torchsplice.cpu import assemble
from torchsplice.cpu.splice import METHOD_CODES
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.splice import SpliceOptions, splice
from torchsplice.splice.registry import BUILTIN_METHODS, available_methods, get_method

NAMES = [m.name for m in BUILTINS]


def test_every_row_is_registered_and_nothing_else_is_builtin():
    assert BUILTIN_METHODS == tuple(NAMES) == available_methods()[:len(NAMES)]
    for row in BUILTINS:
        m = get_method(row.name)
        assert m.builtin and m.compiled and builtin(row.name) is row
        assert (m.description, m.needs_reference, m.diagnostics) == (row.description, row.needs_reference, row.diagnostics)
        assert m.uses_acting_limbs == row.acting_limbs
        assert m.clip_name("L", "A") == ("L+A." + row.name if row.suffix else "L+A")
        assert callable(resolve(row.run)) and callable(resolve(row.standing))
    assert builtin("no-such-method") is None


def test_every_row_has_its_own_kernel_code():
    assert METHOD_CODES == {m.name: m.code for m in BUILTINS}
    assert len(set(METHOD_CODES.values())) == len(BUILTINS)
    assert all(isinstance(c, int) and c >= 0 for c in METHOD_CODES.values())
    # the ints the kernels branch on (numba freezes them) are the table's
    assert (assemble.SPLICE_CODE, assemble.NAIVE_CODE, assemble.CPMC_CODE) == tuple(
        METHOD_CODES[n] for n in ("splice", "naive", "cpmc"))


def test_the_table_is_consistent():
    for row in BUILTINS:
        assert row.aligns_time == ("cost" in row.diagnostics) == ("crop" in row.diagnostics)
        assert row.stores in ("parts", "frames")
    assert sum(not row.suffix for row in BUILTINS) == 1 and not BUILTINS[0].suffix  # the default's results: LOCO+ACTION


@pytest.mark.parametrize("backend", ["compiled", "torch"])
@pytest.mark.parametrize("name", NAMES)
def test_what_the_table_says_is_what_a_splice_does(name, backend):
    row = builtin(name)
    clips = {m.name: m for m in sample_motions(torch.float64)}
    spec = load_spec("sample")
    ref = clips["walk_straight"] if row.needs_reference else None
    r = splice(clips["walk_curve"], clips["carry_box"], spec, name, ref, SpliceOptions(dtype=torch.float64, backend=backend))
    assert r.method == name and r.motion.name == get_method(name).clip_name("walk_curve", "carry_box")
    assert math.isfinite(r.cost) == row.aligns_time
