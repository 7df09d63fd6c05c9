"""Every option is declared once, in the library: the command line's choices and defaults are
the library's (its registries, constants and option dataclasses), checked here by walking the
parser's actions, so that the two cannot drift apart. Both read them from the packages'
torch-free ``defaults`` modules, so a parser built without torch holds the same values
(checked in a fresh process); every export format's declared options are flags."""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import logging
import subprocess
import sys

import pytest

from torchsplice.cli import build_parser
from torchsplice.evaluation.report import evaluate_database
from torchsplice.formats.exporters import DEFAULT_FORMAT, available_exporters, export_clips, get_exporter
from torchsplice.formats.importer import FORMATS as IMPORT_FORMATS, import_bvh
from torchsplice.formats.npz import FEATURE_SETS
from torchsplice.retarget import retarget_clips
from torchsplice.retarget.mirror import mirror_clips
from torchsplice.job.config import DEFAULT_ACTIONS, DEFAULT_LOCOMOTIONS, LAYOUTS, STORES, JobConfig, job_config
from torchsplice.job.engines import available_engines
from torchsplice.job.materialize import materialize
from torchsplice.job.merge import merge_job
from torchsplice.job.pair import splice_pair
from torchsplice.splice import SpliceOptions, TIMINGS, splice
from torchsplice.splice.registry import available_methods
from torchsplice.splice.standing import parse_limbs
from torchsplice.store.database import COMPRESSIONS
from torchsplice.splice.backends import backend_choices
from torchsplice.viz.render import CAMERAS, render
from torchsplice.viz.viewer import write_viewer


def param(fn, name):
    return inspect.signature(fn).parameters[name].default


JOB = {f.name: f.default for f in dataclasses.fields(JobConfig) if f.default is not dataclasses.MISSING}
ONE = SpliceOptions()  # the options of splice and plot-alignment


def _splice_flags(o, force) -> dict:
    """The splice's flags' defaults as the library states them (``o``: JobConfig fields or SpliceOptions)."""
    get = o.get if isinstance(o, dict) else lambda k: getattr(o, k)
    return {"max_run": get("max_run") if isinstance(o, dict) else o.align.max_run, "no_posture": not get("posture"),
            "twist": get("twist"), "timing": get("timing"), "force_locomotion": force, "device": get("device"),
            "backend": get("backend")}


def expected() -> dict:
    """(command, dest) -> (the library's default, the library's choices or None), as the
    registries stand now (other tests register plug-in methods and formats)."""
    return {
        ("import", "spec"): (param(import_bvh, "spec"), None),
        ("import", "units"): (param(import_bvh, "units"), None),
        ("import", "window"): (param(import_bvh, "window"), None),
        ("import", "window_overlap"): (param(import_bvh, "window_overlap"), None),
        ("import", "float64"): (param(import_bvh, "float64"), None),
        ("import", "append"): (param(import_bvh, "append"), None),
        ("import", "format"): (param(import_bvh, "format"), IMPORT_FORMATS),
        ("import", "name_prefix"): (param(import_bvh, "name_prefix"), None),
        ("retarget", "fix_feet"): (param(retarget_clips, "fix_feet"), None),
        ("mirror", "originals"): (param(mirror_clips, "originals"), None),
        ("export", "index"): (param(export_clips, "index"), None),
        ("export", "format"): (None, available_exporters()),
        # every format's options (None: the format's own default, which export_clips fills in)
        **{("export", k): (None, o.choices) for f in available_exporters() for k, o in get_exporter(f).options.items()},
        ("splice", "method"): (param(splice, "method"), available_methods()),
        ("splice", "keep_hands_out"): (param(splice_pair, "keep_hands_out"), None),
        ("render", "frames"): (param(render, "frames"), None),
        ("render", "max_seconds"): (param(render, "max_seconds"), None),
        ("render", "camera"): (param(render, "camera"), CAMERAS),
        ("render", "azimuth"): (param(render, "azimuth"), None),
        ("render", "elevation"): (param(render, "elevation"), None),
        ("view", "max_clips"): (param(write_viewer, "max_clips"), None),
        ("evaluate", "max_rows"): (param(evaluate_database, "max_rows"), None),
        ("evaluate", "no_pictures"): (not param(evaluate_database, "pictures"), None),
        ("splice-all", "method"): (",".join(JOB["methods"]), None),
        ("splice-all", "memory_budget"): (JOB["memory_budget_mb"], None),
        ("splice-all", "batch_size"): (JOB["batch_pairs"], None),
        ("splice-all", "copy_sources"): (JOB["copy_sources"], None),
        ("splice-all", "index"): (JOB["index"], None),
        ("merge", "index"): (param(merge_job, "index"), None),
        ("materialize", "index"): (param(materialize, "index"), None),
        ("splice-all", "max_length_ratio"): (JOB["max_length_ratio"], None),
        ("splice-all", "engine"): (JOB["engine"], available_engines()),
        ("splice-all", "workers"): (JOB["workers"], None),
        ("splice-all", "ray_address"): (JOB["ray_address"], None),
        ("splice-all", "actions_db"): (JOB["actions_db"], None),
        ("splice-all", "retarget"): (JOB["retarget"], None),
        ("splice-all", "fix_feet"): (JOB["fix_feet"], None),
        ("splice-all", "keep_hands_out"): (JOB["keep_hands_out"], None),
        ("splice-all", "target"): (JOB["target"], None),
        ("splice-all", "layout"): (JOB["layout"], LAYOUTS),
        ("splice-all", "store"): (JOB["store"], STORES),
        ("splice-all", "compression"): (JOB["compression"] or "none", None),  # choices: see below
        **{(c, k): (v, TIMINGS if k == "timing" else backend_choices() if k == "backend" else None)
           for c, o, force in (("splice", ONE, ONE.force), ("splice-all", JOB, JOB["force_locomotion"]))
           for k, v in _splice_flags(o, force).items()},
        **{("plot-alignment", k): (v, backend_choices() if k == "backend" else None) for k, v in _splice_flags(ONE, True).items()
           if k not in ("timing", "force_locomotion")},  # plot-alignment always time-aligns: set, not flags
    }


def subparsers() -> dict[str, argparse.ArgumentParser]:
    p = build_parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_every_choice_and_default_is_the_librarys():
    checked, EXPECTED = set(), expected()
    for command, s in subparsers().items():
        for a in s._actions:
            if isinstance(a, argparse._HelpAction) or not a.option_strings:
                continue
            if a.help == argparse.SUPPRESS and a.default == argparse.SUPPRESS:
                continue  # an unlisted earlier name of a listed option (import --split): no default of its own
            key = (command, a.dest)
            if key in EXPECTED:
                default, choices = EXPECTED[key]
                assert a.default == default and type(a.default) is type(default), (key, a.default, default)
                if choices is not None:
                    assert tuple(a.choices) == tuple(choices), (key, a.choices, choices)
                checked.add(key)
            # an option with a value of its own or choices must be checked against the library here
            elif a.choices is not None or a.default not in (None, False):
                assert key in ALLOWED_CLI_ONLY, f"{key}: default {a.default!r}, choices {a.choices!r} not checked"
    assert checked == set(EXPECTED)


ALLOWED_CLI_ONLY = {  # options that are the command line's own (no library option behind them)
    ("splice-all", "log_level"),  # logging levels: checked below
    ("splice-all", "acting_limbs"), ("splice", "acting_limbs"),  # spelt "auto": checked below
}


def test_choices_and_spellings_of_the_command_lines_own():
    s = subparsers()
    acts = {(c, a.dest): a for c, p in s.items() for a in p._actions}
    comp = acts[("splice-all", "compression")]
    assert set(comp.choices) == {"none" if c is None else c for c in COMPRESSIONS}
    assert comp.default == (JOB["compression"] or "none")
    for level in acts[("splice-all", "log_level")].choices:
        assert isinstance(getattr(logging, level.upper()), int)
    assert parse_limbs(acts[("splice", "acting_limbs")].default) == ONE.acting_limbs
    assert parse_limbs(acts[("splice-all", "acting_limbs")].default) == JOB["acting_limbs"]
    # the defaults plot-alignment sets (it always time-aligns, whatever --timing would say)
    plot = s["plot-alignment"]
    assert plot.get_default("timing") == ONE.timing and plot.get_default("force_locomotion") is True
    assert parse_limbs(plot.get_default("acting_limbs")) == ONE.acting_limbs
    # the flags' defaults make the library's configuration
    args = build_parser().parse_args(["splice-all", "db.h5", "-o", "out.h5"])
    assert args.locomotions is None and args.actions is None  # job_config turns them into the defaults
    assert job_config("db.h5", "out.h5", locomotions=None, actions=None).locomotions == DEFAULT_LOCOMOTIONS
    assert job_config("db.h5", "out.h5").actions == DEFAULT_ACTIONS
    assert DEFAULT_FORMAT in available_exporters()


def test_the_export_formats_options_are_their_flags():
    """Each option a format declares is a flag with its type, choices and help (after the name of
    the format that takes it; none for the options of every export); the npz format's choices are
    its feature sets."""
    acts = {a.dest: a for a in subparsers()["export"]._actions}
    assert acts["features"].choices == tuple(FEATURE_SETS) and acts["features"].help.startswith("npz: add 6D")
    assert acts["packed"].nargs == 0 and acts["packed"].help.startswith("npz: one file")
    assert acts["paraphrases"].type is int and acts["paraphrases"].metavar == "N"
    assert acts["paraphrases"].help == "humanml3d: captions per clip, at most (default: 3)"
    assert acts["split_seed"].help == "the seed of the split (default: 0)"  # every export's: no format named
    args = build_parser().parse_args(["export", "db.h5", "--all", "-o", "out", "--packed", "--features", "6d"])
    assert (args.packed, args.features, args.mirror, args.window) == (True, "6d", None, None)
    assert set(args.format_options) >= {"packed", "features", "captions", "mirror", "window", "split_ratios",
                                        "split_seed", "paraphrases", "shards"}


@pytest.mark.parametrize("command", ["splice", "splice-all", "export", "import", "render", "retarget"])
def test_help_without_torch_shows_the_librarys_values(command):
    """In a fresh process (no torch loaded: values read from the source) the parser holds the
    same choices and defaults as here (library imported)."""
    probe = ("import sys, json, argparse\nfrom torchsplice.cli import build_parser\n"
             "p = build_parser()\nsub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))\n"
             f"s = sub.choices[{command!r}]\n"
             "print(json.dumps({a.dest: [a.default, list(a.choices) if a.choices else None] for a in s._actions "
             "if a.option_strings and a.dest != 'help'}))\n"
             "print('torch' in sys.modules)")
    p = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    import json

    values, loaded = p.stdout.strip().splitlines()
    here = {a.dest: [a.default, list(a.choices) if a.choices else None] for a in subparsers()[command]._actions
            if a.option_strings and a.dest != "help"}
    fresh = json.loads(values)
    if command == "export":  # the flags of plug-in formats other tests registered here (toy_exporter's --decimals)
        from torchsplice.formats.exporters import _BUILTIN_MODULES, _REGISTRY

        plugins = {o for e in _REGISTRY.values() if e.__module__ not in _BUILTIN_MODULES for o in e.options}
        here = {dest: v for dest, v in here.items() if dest in fresh or dest not in plugins}
    for dest in ("method", "format", "engine"):  # registries: here they may hold other tests' plug-ins too
        if dest in fresh and fresh[dest][1] is not None:
            assert fresh[dest][1] == here[dest][1][:len(fresh[dest][1])]
            fresh[dest][1] = here[dest][1]
    assert fresh == json.loads(json.dumps(here)) and loaded == "False"
