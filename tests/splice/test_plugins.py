"""Splicing methods as plug-ins (:mod:`torchsplice.splice.registry`).

A toy method (the action's upper body, frame by frame, a fixed number of frames ahead) is
written as a plug-in module in a temporary folder and runs, unchanged, through ``splice``,
``splice_pairs``, the ``splice-all`` job (Python API; the command line with worker processes,
through ``--plugin``, ``TORCHSPLICE_PLUGINS`` and an entry point) and ``evaluate``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import torch

from torchsplice.core.errors import TorchspliceError
from torchsplice.store.database import MotionDatabase
from torchsplice.splice import SpliceOptions, splice, splice_pairs
from torchsplice.splice.registry import (BUILTIN_METHODS, Method, available_methods, get_method,
                                         load_plugins, plugin_modules, register_method)

OFFSET = 5
TOY = textwrap.dedent(f'''
    """A toy plug-in: the action's upper body, frame by frame, OFFSET frames ahead."""
    import torch

    from torchsplice.splice.clips import without_fk
    from torchsplice.splice.methods import upper_mask
    from torchsplice.splice.registry import Method, MethodOutput, register_method

    OFFSET = {OFFSET}


    def shifted_upper(inp):
        """Result frame t: the locomotion, with the action's upper body of frame t + OFFSET."""
        J = inp.skeleton.num_joints
        lengths = torch.minimum(inp.loco.lengths, inp.act.lengths - OFFSET).clamp(min=1)
        T = int(lengths.max())
        t = torch.arange(T, device=lengths.device)
        src = torch.minimum(t[None] + OFFSET, (inp.act.lengths - 1)[:, None])  # (B, T) action frames
        a_rot = inp.act.rotations.gather(1, src[:, :, None, None].expand(-1, -1, J, 4))
        upper = upper_mask(inp.roles, J, lengths.device)
        rot = torch.where(upper[:, None], a_rot, inp.loco.rotations[:, :T])
        return MethodOutput(without_fk(rot, inp.loco.translations[:, :T].clone(), lengths), src.double())


    register_method(Method("shifted_upper", "the action's upper body, {OFFSET} frames ahead", shifted_upper))
''')


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("plugin")
    (d / "toy_methods.py").write_text(TOY)
    return d


@pytest.fixture(scope="module")
def toy(plugin_dir) -> Method:
    sys.path.insert(0, str(plugin_dir))
    try:
        assert load_plugins(["toy_methods"]) in (["shifted_upper"], [])
    finally:
        sys.path.remove(str(plugin_dir))
    return get_method("shifted_upper")


def _env(paths, **extra) -> dict:
    """The environment of a subprocess: ``paths`` on PYTHONPATH, no plug-ins but those in ``extra``."""
    e = {k: v for k, v in os.environ.items() if k != "TORCHSPLICE_PLUGINS"}
    e.update(OMP_NUM_THREADS="1", **extra)
    e["PYTHONPATH"] = os.pathsep.join([str(p) for p in paths] + [p for p in [os.environ.get("PYTHONPATH")] if p])
    return e


def _cli(plugin_dir, *argv, **env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "torchsplice", *map(str, argv)], capture_output=True, text=True,
                          env=_env([plugin_dir], **env), timeout=600)


def _check_toy(result, loco, act, roles):
    """Known answer: lower body and root from the locomotion, upper body from the action OFFSET frames on."""
    n = result.motion.num_frames
    assert n == min(loco.num_frames, act.num_frames - OFFSET)
    upper = sorted(roles.upper_body)
    lower = [j for j in range(loco.skeleton.num_joints) if j not in upper]
    rot = result.motion.rotations
    assert torch.equal(rot[:, upper], act.rotations[OFFSET:OFFSET + n, upper].to(rot.dtype))
    assert torch.equal(rot[:, lower], loco.rotations[:n, lower].to(rot.dtype))
    assert torch.equal(result.motion.root_translation, loco.root_translation[:n].to(rot.dtype))
    assert torch.equal(result.curve, torch.arange(OFFSET, OFFSET + n, dtype=torch.float64))


def test_registry_lists_builtins_first():
    names = available_methods()
    assert names[:3] == BUILTIN_METHODS
    for name in BUILTIN_METHODS:
        m = get_method(name)
        assert m.builtin and m.compiled and m.standing is not None and m.description
    assert get_method("cpmc").needs_reference and not get_method("naive").needs_reference
    assert plugin_modules(BUILTIN_METHODS) == []


def test_registry_refuses_bad_methods(toy):
    with pytest.raises(TorchspliceError, match="unknown method 'nope'; choose one of splice, naive, cpmc.*shifted_upper"):
        get_method("nope")
    with pytest.raises(TorchspliceError, match="already registered"):
        register_method(Method("naive", "another naive", lambda inp: None))
    with pytest.raises(TorchspliceError, match="lower case"):
        register_method(Method("Bad Name", "x", lambda inp: None))
    with pytest.raises(TorchspliceError, match="cannot be imported"):
        load_plugins(["no_such_plugin_module_xyz"])
    assert register_method(toy) == toy  # registering the same method again is harmless
    assert plugin_modules(["splice", "shifted_upper"]) == ["toy_methods"]


def test_toy_method_known_answer(toy, sample_db):
    with MotionDatabase.open(sample_db) as db:
        loco, act, wave = db.read("walk_curve"), db.read("carry_box"), db.read("wave")
    from torchsplice.specs import load_spec

    spec = load_spec("sample")
    roles = spec.bind(loco.skeleton)
    r = splice(loco, act, spec, method="shifted_upper")
    assert r.method == "shifted_upper" and r.motion.name == "walk_curve+carry_box.shifted_upper"
    assert r.motion.labels["method"] == "shifted_upper" and r.motion.role == "spliced"
    assert r.path.shape == (0, 2) and r.crop == 0 and r.posture_deg == 0 and r.cost != r.cost  # not measured: NaN
    _check_toy(r, loco, act, roles)
    # batched, and whatever the backend asked for (a plug-in runs in torch)
    rs = splice_pairs([(loco, act), (loco, wave)], spec, method=toy)
    rc = splice_pairs([(loco, act), (loco, wave)], spec, method="shifted_upper", options=SpliceOptions(backend="torch"))
    for a, b, ac in zip(rs, rc, (act, wave)):
        _check_toy(a, loco, ac, roles)
        assert torch.equal(a.motion.rotations, b.motion.rotations)


def test_toy_method_in_the_job_api_and_evaluate(toy, sample_db, tmp_path):
    from torchsplice.job import JobConfig, SpliceJob

    out = tmp_path / "out.h5"
    summary = SpliceJob(JobConfig(database=sample_db, output=out, methods=("naive", "shifted_upper"), workers=1),
                        progress=False).run()
    assert summary.spliced == 2 * 25  # 5 locomotions x 5 actions, each method
    with MotionDatabase.open(out) as db:
        names = [str(n) for n in db.table()["name"]]
        got = db.read("walk_curve+carry_box.shifted_upper")
    assert "walk_curve+carry_box.naive" in names
    with MotionDatabase.open(sample_db) as db:
        loco, act = db.read("walk_curve"), db.read("carry_box")
    from torchsplice.evaluation.report import evaluate_database
    from torchsplice.specs import load_spec

    ref = splice(loco, act, load_spec("sample"), method="shifted_upper")
    assert torch.equal(got.rotations, ref.motion.rotations.to(got.rotations.dtype))
    report = tmp_path / "report.md"
    agg = evaluate_database(out, report, pictures=False)
    assert {"naive", "shifted_upper"} <= set(agg)  # the figures per method, the plug-in's among them
    text = report.read_text()
    assert "shifted_upper" in text and text.index("naive") < text.index("shifted_upper")


@pytest.mark.slow  # worker processes in a fresh process, about 11 s: CI and --all run it
def test_toy_method_on_the_command_line_with_workers(plugin_dir, sample_db, tmp_path):
    """``--plugin`` in the driver; the plan records the module, so the two worker processes import it."""
    out = tmp_path / "cli.h5"
    p = _cli(plugin_dir, "--plugin", "toy_methods", "splice-all", sample_db, "-o", out, "--method", "splice,shifted_upper",
             "--workers", "2", "--batch-size", "4", "-q")
    assert p.returncode == 0, p.stderr
    with MotionDatabase.open(out) as db:
        methods = [str(m) for m in db.table()["method"]]
    assert methods.count("shifted_upper") == methods.count("splice") == 25
    # the same method through TORCHSPLICE_PLUGINS, one pair, as BVH
    bvh = tmp_path / "one.bvh"
    p = _cli(plugin_dir, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box", "-o", bvh,
             "--method", "shifted_upper", TORCHSPLICE_PLUGINS="toy_methods")
    assert p.returncode == 0, p.stderr
    assert "shifted_upper of carry_box onto walk_curve" in p.stdout
    # without the plug-in: one line naming the methods there are
    p = _cli(plugin_dir, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box", "-o",
             tmp_path / "two.bvh", "--method", "shifted_upper")
    assert p.returncode == 2 and "argument --method: invalid choice: 'shifted_upper'" in p.stderr
    p = _cli(plugin_dir, "splice-all", sample_db, "-o", tmp_path / "three.h5", "--method", "naive,shifted_upper")
    assert p.returncode == 2 and p.stderr.strip().splitlines() == [
        "torchsplice: error: unknown method 'shifted_upper'; choose one of splice, naive, cpmc"]
    p = _cli(plugin_dir, "--plugin", "no_such_plugin_xyz", "info", sample_db)
    assert p.returncode == 2 and "plug-in module 'no_such_plugin_xyz' cannot be imported" in p.stderr


def test_entry_point_plugin(plugin_dir, tmp_path):
    """An installed package declaring ``[torchsplice.methods]`` registers its methods by itself."""
    dist = tmp_path / "toy_methods_pkg-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-methods-pkg\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[torchsplice.methods]\ntoy = toy_methods\n")
    code = "from torchsplice.splice.registry import available_methods; print(','.join(available_methods()))"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=_env([plugin_dir, tmp_path]))
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["splice,naive,cpmc,shifted_upper"]


def test_a_plug_in_methods_motions_are_kept_whole_in_an_alignment_store(toy, plugin_dir, sample_db, tmp_path):
    """A plug-in's result is a motion, not parts: an alignment store keeps its frames beside the
    built-in methods' parts, and reads them as the motion store does."""
    from torchsplice.job import splice_all

    sys.path.insert(0, str(plugin_dir))
    try:
        out = {}
        for store in ("motion", "alignment"):
            out[store] = tmp_path / f"{store}.h5"
            splice_all(sample_db, out[store], store=store, methods="splice,shifted_upper", workers=1, index=False)
    finally:
        sys.path.remove(str(plugin_dir))
    with MotionDatabase.open(out["alignment"]) as a, MotionDatabase.open(out["motion"]) as m:
        kinds = a.h5["clips/assembly_kind"][()]
        methods = a.table()["method"]
        assert set(kinds[methods == "shifted_upper"].tolist()) == {-1} and set(kinds[methods == "splice"].tolist()) == {1}
        assert a.names == m.names
        for x, y in zip(a.read_many(range(len(a))), m.read_many(range(len(m)))):
            assert torch.equal(x.rotations, y.rotations) and torch.equal(x.root_translation, y.root_translation)
