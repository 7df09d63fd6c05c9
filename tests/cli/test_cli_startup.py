"""The command line starts light: ``--version`` and ``--help`` load no torch, numba, h5py or
matplotlib (they are imported by the commands that use them); and ``info --json`` gives a
spliced database's run record."""

from __future__ import annotations

import json
import subprocess
import sys

import h5py

from torchsplice.cli import main

HEAVY = ("torch", "numba", "h5py", "matplotlib", "numpy", "tqdm")
PROBE = """
import sys
import torchsplice.cli as cli
for argv in {argvs!r}:
    try:
        cli.main(argv)
    except SystemExit as exc:
        assert exc.code == 0, (argv, exc.code)
print("loaded:" + ",".join(m for m in {heavy!r} if m in sys.modules))
"""


def test_version_and_help_load_no_heavy_module():
    argvs = [["--version"], ["--help"]] + [[c, "--help"] for c in ("import", "info", "splice", "splice-all",
                                                                      "evaluate", "render", "merge", "export",
                                                                      "retarget", "mirror", "view", "materialize")]
    p = subprocess.run([sys.executable, "-c", PROBE.format(argvs=argvs, heavy=HEAVY)], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == "loaded:"  # none of them was imported
    assert "torchsplice 0.1.0" in p.stdout and "splice,naive,cpmc" in p.stdout.replace(", ", ",")


def test_info_json_has_the_run_record(tmp_path, capsys):
    db, out = tmp_path / "sample.h5", tmp_path / "out.h5"
    assert main(["sample", "-o", str(db), "-q"]) == 0
    assert main(["info", str(db), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["run"] is None  # not written by a job
    assert main(["splice-all", str(db), "-o", str(out), "--method", "naive", "--workers", "1", "-q"]) == 0
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0
    run = json.loads(capsys.readouterr().out)["run"]
    with h5py.File(out, "r") as f:
        assert run == json.loads(f.attrs["run"])
    assert run["methods"] == ["naive"] and run["command"].startswith("torchsplice splice-all")
    assert main(["info", str(out)]) == 0
    assert f"run: {run['command']}" in capsys.readouterr().out


def test_a_command_line_declares_only_its_commands_options(monkeypatch):
    """Start-up builds only the named command's flags (every command's for ``--help`` or a
    mistyped command: their registries are read then), and that command parses as it does with
    every one built."""
    from torchsplice.cli.base import registered_commands
    from torchsplice.cli.main import _command_in, build_parser

    assert _command_in(["--plugin", "mymod", "info", "db.h5"]) == "info"
    assert _command_in(["--plugin=mymod", "-h"]) is None and _command_in([]) is None
    build_parser()  # every command registered
    built: list[str] = []
    for command in registered_commands():
        def spy(parser, _add=command.add_arguments, _name=command.name):
            built.append(_name)
            _add(parser)
        monkeypatch.setattr(command, "add_arguments", spy)
    argv = ["render", "db.h5", "walk", "-o", "x.png", "--camera", "world", "--overlay", "a", "b"]
    one = build_parser(only="render")
    assert built == ["render"]
    built.clear()
    every = build_parser(only=None)
    assert built == [c.name for c in registered_commands()]
    a, b = vars(one.parse_args(argv)), vars(every.parse_args(argv))
    assert {k: v for k, v in a.items() if k not in ("func", "cli_command")} == \
        {k: v for k, v in b.items() if k not in ("func", "cli_command")}
    built.clear()
    build_parser(only="splce-all")  # a mistyped command: every command's, as for --help
    assert built == [c.name for c in registered_commands()]
