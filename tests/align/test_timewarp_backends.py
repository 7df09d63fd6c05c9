"""Which DP the timewarp runs: the registered splicing backends' choice
(:attr:`~torchsplice.splice.backends.Backend.dynamic_program`,
:func:`~torchsplice.splice.backends.dynamic_program_for`), with no table of its own.

``"auto"`` runs the DP of the available backend of highest priority that runs on the grid's
device (the compiled DP on the CPU, torch without numba); a name runs that backend's; a backend
registered in a test (then unregistered) is the one the timewarp uses on its device, its own DP
or, if it gives none, the torch DP.
"""

from __future__ import annotations

import pytest
import torch

import torchsplice.cpu
from torchsplice.align import timewarp as tw
from torchsplice.align.timewarp import DynamicProgram, cumulative_cost, timewarp
from torchsplice.splice.backends import Backend

DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)]


@pytest.fixture
def ran(monkeypatch):
    """The names of the DPs run, in order: the built-in DPs replaced by spies that say so."""
    calls: list[str] = []
    for name in ("TORCH_DP", "COMPILED_DP"):
        monkeypatch.setattr(tw, name, _spy(getattr(tw, name), name, calls))
    return calls


def _spy(program: DynamicProgram, name: str, calls: list[str]) -> DynamicProgram:
    def wrap(f):
        def run(*args):
            calls.append(name)
            return f(*args)
        return run

    return DynamicProgram(wrap(program.timewarp), wrap(program.cumulative))


@pytest.fixture
def registry(monkeypatch):
    """The splicing backends' registry, with registrations undone after the test."""
    import torchsplice.splice.backends as backends

    monkeypatch.setattr(backends, "_REGISTRY", dict(backends._REGISTRY))
    monkeypatch.setattr(backends, "_INSTANCES", dict(backends._INSTANCES))
    return backends


def _backend(name: str, devices, priority: int, program: DynamicProgram | None = None) -> type:
    """A backend class declaring ``devices`` and ``priority``, with ``program`` as its DP (else the default)."""
    attrs = {"name": name, "devices": devices, "priority": priority}
    if program is not None:
        attrs["dynamic_program"] = property(lambda self: program)
    return type(name, (Backend,), attrs)


def _unregister(registry, name: str) -> None:
    registry._REGISTRY.pop(name)
    registry._INSTANCES.pop(name, None)


def test_the_dp_is_the_registered_backends_choice_by_device_and_priority(ran, monkeypatch):
    """``"auto"`` runs the DP of the available backend of highest priority on the grid's device (the
    compiled DP on the CPU, torch without numba); a name runs that backend's; the errors are one line."""
    g = torch.rand(2, 6, 7, dtype=torch.float64)
    for backend, want in (("auto", "COMPILED_DP"), ("compiled", "COMPILED_DP"), ("torch", "TORCH_DP")):
        ran.clear()
        timewarp(g, backend=backend)
        cumulative_cost(g, backend=backend)
        assert ran == [want, want], backend
    monkeypatch.setattr(torchsplice.cpu, "_AVAILABLE", False)
    ran.clear()
    timewarp(g)
    assert ran == ["TORCH_DP"]
    with pytest.raises(ValueError, match=r"^backend must be 'auto', 'compiled' or 'torch', got 'gpu'$"):
        timewarp(g, backend="gpu")
    with pytest.raises(ValueError, match=r"^backend must be 'auto', 'compiled' or 'torch', got 'gpu'$"):
        cumulative_cost(g, backend="gpu")


@pytest.mark.parametrize("device", DEVICES)
def test_a_backend_registered_for_a_device_is_the_one_the_timewarp_uses_there(ran, registry, device):
    """Registering a backend is all it takes: its DP runs for grids on its device, by ``"auto"``
    (it outranks the built-ins there) and by its name, and nowhere else; once it is unregistered
    the built-in choice is back. Its DP gives the built-in DP's bits here (it wraps torch's)."""
    other = "cuda" if device == "cpu" else "cpu"
    builtin = "COMPILED_DP" if device == "cpu" else "TORCH_DP"
    g = torch.rand(3, 9, 8, dtype=torch.float64)
    want = timewarp(g, backend="torch")
    registry.register_backend("mine", _backend("mine", (device,), 100, _spy(tw.TORCH_DP, "mine", ran)))
    registry.register_backend("elsewhere", _backend("elsewhere", (other,), 200, _spy(tw.TORCH_DP, "elsewhere", ran)))
    ran.clear()
    got = timewarp(g.to(device))
    cum = cumulative_cost(g.to(device), backend="mine")
    assert ran == ["mine", "TORCH_DP", "mine", "TORCH_DP"]  # the backend's DP (wrapping the torch one)
    assert torch.equal(got.cells.cpu(), want.cells) and torch.equal(got.total.cpu(), want.total)
    assert torch.equal(cum.cpu(), cumulative_cost(g, backend="torch"))
    with pytest.raises(ValueError, match=rf"^the elsewhere backend runs on {other.upper()} tensors, got a grid on {device}"):
        timewarp(g.to(device), backend="elsewhere")
    with pytest.raises(ValueError, match=r"^backend must be 'auto', 'compiled', 'torch', 'mine' or 'elsewhere', got 'x'$"):
        timewarp(g, backend="x")
    _unregister(registry, "mine")
    ran.clear()
    timewarp(g.to(device))
    assert ran == [builtin]
    with pytest.raises(ValueError, match=r"^backend must be .* got 'mine'$"):
        timewarp(g.to(device), backend="mine")


def test_a_backend_without_a_dp_of_its_own_runs_the_torch_dp(ran, registry):
    """A backend that gives no DP inherits the torch one, which runs on any device."""
    registry.register_backend("plain", _backend("plain", ("cpu",), 100))
    g = torch.rand(2, 5, 6, dtype=torch.float64)
    ran.clear()
    timewarp(g)
    cumulative_cost(g, backend="plain")
    assert ran == ["TORCH_DP", "TORCH_DP"]
    _unregister(registry, "plain")
    ran.clear()
    timewarp(g)
    assert ran == (["COMPILED_DP"] if torchsplice.cpu.available() else ["TORCH_DP"])
