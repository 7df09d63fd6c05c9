"""Shared fixtures: where the real motion capture lives, and helpers to find its clips.

Real clips are read from ``../shared/mocap`` beside the checkout, or from the folder named
by the ``TORCHSPLICE_MOCAP`` environment variable. Where it is absent, tests that need it are
skipped with the reason; under CI (``CI=true``) its absence is an error instead, so that CI
never passes by skipping.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from realdata import BANDAI, BANDAI_FEW, BANDAI_FOLDER, _require_mocap, copy_bandai


def pytest_configure(config):
    """Under pytest-xdist, the cores are shared out: each test process computes on
    ``cores // processes`` threads (at least one; torch and the compiled kernels). Two processes
    of two threads each on two cores would wait on each other: the whole suite took 769 s that
    way, 526 s with a thread each. A test may still set more threads for itself. The processes
    that tests start get the same share for torch (``OMP_NUM_THREADS``); the compiled kernels
    keep their own defaults there."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0)
    if workers < 2:
        return
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    share = max(1, cores // workers)
    os.environ["OMP_NUM_THREADS"] = str(share)
    import torch

    torch.set_num_threads(share)
    from torchsplice.cpu import available, set_threads

    if available():
        set_threads(share)


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """The folder of real BVH files (one subfolder per source)."""
    return _require_mocap()


@pytest.fixture(scope="session")
def sample_f64():
    """Every clip of the built-in sample by name (float64), its spec and the roles bound to it."""
    import torch

    from torchsplice.sample import sample_motions
    from torchsplice.specs import load_spec

    clips = {m.name: m for m in sample_motions(torch.float64)}
    spec = load_spec("sample")
    return clips, spec, spec.bind(clips["walk_straight"].skeleton)


@pytest.fixture(scope="session")
def sample_db(tmp_path_factory):
    """The built-in sample as a database (what ``torchsplice sample`` writes: every sample clip
    with the sample spec), made once per session; a test module may define its own."""
    from torchsplice import write_sample

    db = tmp_path_factory.mktemp("sample") / "sample.h5"
    write_sample(db)
    return db


@pytest.fixture(scope="session")
def mixed(mocap_dir, tmp_path_factory) -> Path:
    """Two Bandai Namco clips (22 joints) and the CMU walk (31 joints)."""
    from torchsplice import import_bvh

    out = tmp_path_factory.mktemp("mixed") / "mixed.h5"
    bandai = mocap_dir / BANDAI
    files = [bandai / "dataset-1_walk_normal_001.bvh", bandai / "dataset-1_bye_normal_001.bvh",
             mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"]
    report = import_bvh(files, out, units="cm")
    assert not report.skipped and len(report.imported) == 3
    return out


@pytest.fixture(scope="session")
def bandai_namco_db(mocap_dir, tmp_path_factory) -> Path:
    """Every Bandai Namco clip of ../shared/mocap imported as ``import_bvh([FOLDER], db)`` (and
    ``torchsplice import FOLDER``) does (the spec detected), made once per session: read it, never write into it."""
    from torchsplice import import_bvh

    db = tmp_path_factory.mktemp("bandai_namco") / "bandai.h5"
    report = import_bvh([mocap_dir / BANDAI], db)
    assert not report.skipped and report.imported
    return db


@pytest.fixture(scope="session")
def bandai_few_db(mocap_dir, tmp_path_factory) -> Path:
    """The :data:`realdata.BANDAI_FEW` clips (three locomotions, two of both roles, a wave
    performed standing in place) imported with the ``bandai_namco`` spec, made once per session:
    read it, never write into it."""
    from torchsplice import import_bvh

    db = tmp_path_factory.mktemp("bandai_few") / "bandai.h5"
    report = import_bvh([mocap_dir / BANDAI / f"{n}.bvh" for n in BANDAI_FEW], db, spec="bandai_namco")
    assert not report.skipped and len(report.imported) == len(BANDAI_FEW)
    return db


@pytest.fixture(scope="session")
def bandai_f64(mocap_dir):
    """``(read, spec)``: ``read(name)`` is the Bandai Namco clip ``name`` (a file stem) in float64,
    read once per session, and the ``bandai_namco`` spec. The clips are shared by every test:
    copy a tensor before changing it."""
    import torch

    from torchsplice.formats.bvh import read_bvh
    from torchsplice.specs import load_spec

    cache: dict = {}

    def read(name: str):
        if name not in cache:
            cache[name] = read_bvh(mocap_dir / BANDAI / f"{name}.bvh", dtype=torch.float64)
        return cache[name]

    return read, load_spec("bandai_namco")


@pytest.fixture
def bandai_folder(mocap_dir, tmp_path) -> Path:
    """A folder of copies of the :data:`realdata.BANDAI_FOLDER` clips in the test's own
    ``tmp_path`` (a test may add files there or break them)."""
    return copy_bandai(BANDAI_FOLDER, tmp_path / "in")


@pytest.fixture
def bandai_walks(mocap_dir) -> list[Path]:
    """Ten real Bandai Namco walks (paths into the shared folder: read them, never write there)."""
    files = sorted((mocap_dir / BANDAI).glob("dataset-1_walk*.bvh"))[:10]
    assert len(files) == 10
    return files


@pytest.fixture(scope="session")
def runs_with_raised_hands(bandai_namco_db, tmp_path_factory):
    """Bandai Namco runs, dashes and turning walks x raised hands, waves and calls, spliced as
    they come (``raw``, ``keep_hands_out=False``) and with the arms kept out of the body
    (``out``, the default), both motion stores: ``(database, raw, out)``, the database being
    ``bandai_namco_db`` (the whole folder, the ``bandai_namco`` spec detected)."""
    from torchsplice.job.run import splice_all

    folder = tmp_path_factory.mktemp("hands")
    db = bandai_namco_db
    select = dict(locomotions=["*run*,*dash*,*turn*"], actions=["*wave*,*raise*,*bye*,*call*,*guide*"], workers=1)
    splice_all(db, folder / "raw.h5", keep_hands_out=False, **select)
    splice_all(db, folder / "out.h5", **select)
    return db, folder / "raw.h5", folder / "out.h5"


LONGEST_FIRST = ("tests/e2e/test_readme_examples.py::test_every_readme_block_runs_in_order_in_one_fresh_clone",
                 "tests/job/test_ray.py::")
"""Under pytest-xdist, these start first (the walkthrough, 200 to 350 s; the Ray cluster, about
100 s), then every other test marked ``slow``, then the rest: with ``--dist worksteal``
(scripts/test.sh) the other process takes the quick tests, and whichever runs out first takes
half of the other's queue, so the run does not end waiting on one long test begun late."""


def _run_order(item) -> int:
    if any(item.nodeid.startswith(first) for first in LONGEST_FIRST):
        return 0
    return 1 if item.get_closest_marker("slow") else 2


def pytest_collection_modifyitems(config, items):
    """Tests marked ``gpu`` skip, saying so, where torch sees no CUDA device; under pytest-xdist
    the longest tests come first (:data:`LONGEST_FIRST`; a stable sort, each group in its order)."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        items.sort(key=_run_order)
    gpu = [item for item in items if item.get_closest_marker("gpu")]
    if not gpu:
        return
    import torch

    if not torch.cuda.is_available():
        for item in gpu:
            item.add_marker(pytest.mark.skip(reason="gpu: no CUDA device on this machine"))
