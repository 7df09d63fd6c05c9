"""The snippets of the README and of the documentation's pages run as written, on real Bandai
Namco clips, each read from the page it lives on (``docs/*.md``), so the pages cannot drift
from the code.

The README's three commands and its Python give the same database; the training snippet
(docs/training.md) filters a spliced database by the action's style label and reads the
character's trajectory; the h5py snippet (docs/python.md) reads the layout with plain h5py; and,
marked slow, every block of the README and of the pages, in the site's order, runs in one fresh
clone as a reader runs them.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest
import torch

from torchsplice.cli import main

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
DOCS = REPO / "docs"
BANDAI = ["dataset-1_walk_normal_001", "dataset-2_walk-turn-left_normal_025",
          "dataset-1_walk_old_001", "dataset-1_walk_proud_001", "dataset-1_walk_sad_001"]


def page_path(page: str) -> Path:
    """``README.md``, or a documentation page by its path under ``docs/`` (``training.md``)."""
    return README if page == "README.md" else DOCS / page


def snippet(after_heading: str, page: str = "README.md") -> str:
    """The first ```python block after the heading ``after_heading`` on ``page``."""
    text = page_path(page).read_text()
    start = text.index(after_heading)
    m = re.search(r"```python\n(.*?)```", text[start:], re.S)
    assert m, f"no python block after {after_heading!r} in {page}"
    return m.group(1)


def run_snippet(code: str, page: str, scope: dict) -> None:
    exec(compile(code, str(page_path(page)), "exec"), scope)


@pytest.fixture(scope="module")
def spliced(mocap_dir, tmp_path_factory) -> Path:
    """``spliced.h5``: the Bandai Namco styled walks spliced onto two normal-style locomotions."""
    root = tmp_path_factory.mktemp("readme")
    folder = root / "bvh"
    folder.mkdir()
    for stem in BANDAI:
        shutil.copy(mocap_dir / "bandai_namco_research_motiondataset" / f"{stem}.bvh", folder)
    assert main(["import", str(folder), "-o", str(root / "bandai.h5"), "-q"]) == 0
    assert main(["splice-all", str(root / "bandai.h5"), "-o", str(root / "spliced.h5"), "-q",
                 "--locomotions", "role:locomotion", "--actions", "role:both", "--workers", "1"]) == 0
    return root


def test_the_training_snippet_runs_and_selects_by_the_actions_style(spliced, monkeypatch):
    code = snippet("# Reading the output for training", "training.md")
    assert '"labels.action.style"' in code and '"trajectory"' in code
    monkeypatch.chdir(spliced)
    scope: dict = {}
    run_snippet(code.replace("...", "pass"), "training.md", scope)
    ds, batch = scope["ds"], scope["batch"]
    styles = {ds.table["labels"][i] for i in range(ds.num_clips)}
    assert ds.num_clips == 4  # old and proud, each onto two locomotions; sad is filtered out
    assert all('"action.style": "old"' in s or '"action.style": "proud"' in s for s in styles)
    assert all('"locomotion.style": "normal"' in s for s in styles)
    traj = batch["trajectory"]
    assert traj.shape[-1] == 3 and traj.shape[:2] == batch["rotations"].shape[:2]


def test_the_trajectory_is_the_characters_world_position_where_root_translation_stands_still(spliced):
    from torchsplice.data import MotionDataset
    from torchsplice.kinematics import forward_kinematics  # noqa: F401 (the public FK, as users call it)

    ds = MotionDataset(spliced / "spliced.h5", features=("root_translation", "trajectory", "positions"))
    item = ds[0]
    assert torch.count_nonzero(item["root_translation"]) == 0  # Bandai's joint_Root stays at the origin
    hips = ds.skeletons[0].names.index("Hips")
    assert torch.equal(item["trajectory"], item["positions"][:, hips])
    travel = (item["trajectory"][-1] - item["trajectory"][0])[[0, 2]].norm()
    assert travel > 100  # centimetres: the character walks, it does not walk in place


def test_the_h5py_snippet_runs_and_names_the_trajectory_joint(spliced, monkeypatch):
    code = snippet("## Reading a database without torchsplice", "python.md")
    monkeypatch.chdir(spliced)
    shutil.copy(spliced / "bandai.h5", spliced / "clips.h5")
    code = code.replace('names.index("walk_straight")', 'names.index("dataset-1_walk_old_001")')
    scope: dict = {}
    run_snippet(code, "python.md", scope)
    assert scope["trajectory_joint"] == "Hips"
    assert scope["rotations"].shape[1:] == (22, 4) and scope["labels"]["style"] == "old"
    os.remove(spliced / "clips.h5")


def test_a_single_splice_keeps_its_sources_labels_too(spliced):
    from torchsplice.store.database import MotionDatabase
    from torchsplice.specs import DatasetSpec
    from torchsplice.splice import splice

    with MotionDatabase.open(spliced / "bandai.h5") as db:
        loco, act = db.read("dataset-1_walk_normal_001"), db.read("dataset-1_walk_old_001")
        spec = DatasetSpec.from_json(db.spec_json(db.clip_info(loco.name)["skeleton"]))
    for method in ("splice", "naive"):
        labels = splice(loco, act, spec, method=method).motion.labels
        assert labels["action.style"] == "old" and labels["locomotion.style"] == "normal"
        assert labels["method"] == method and labels["action"] == act.name


def test_the_pipeline_snippet_imports_and_splices_like_the_commands(spliced, tmp_path, monkeypatch, capsys):
    """``import_bvh`` then ``splice_all`` give the clips ``torchsplice import`` and ``splice-all`` gave."""
    import h5py
    import numpy as np

    code = snippet("## The whole pipeline from Python", "python.md")
    shutil.copytree(spliced / "bvh", tmp_path / "bvh")
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    run_snippet(code, "python.md", scope)
    report, summary = scope["report"], scope["summary"]
    assert sorted(c.name for c in report.imported) == sorted(BANDAI) and report.skipped == []
    assert "spliced" in capsys.readouterr().out
    with h5py.File(spliced / "spliced.h5", "r") as f:
        cli_names = list(f["clips/name"].asstr()[()])
        cli_rot = f["skeletons/0/rotations"][()]
    with h5py.File(tmp_path / "spliced.h5", "r") as f:
        names = list(f["clips/name"].asstr()[()])
        methods = list(f["clips/method"].asstr()[()])
        starts, lengths = f["clips/start"][()], f["clips/length"][()]
        rot = f["skeletons/0/rotations"][()]
    assert summary.spliced == len(names) == 2 * len(cli_names)
    assert sorted(n for n, m in zip(names, methods) if m == "splice") == sorted(cli_names)
    kept = np.concatenate([rot[s:s + n] for s, n, m in zip(starts, lengths, methods) if m == "splice"])
    assert np.array_equal(kept, cli_rot)  # the splice method's clips, bit for bit (both in plan order)


def test_the_plugin_snippet_registers_a_method_every_command_takes(spliced):
    """The "Plug-in methods" snippet: the locomotion unchanged, spliced through the registry."""
    from torchsplice.store.database import MotionDatabase
    from torchsplice.splice import splice
    from torchsplice.splice.registry import available_methods, get_method
    from torchsplice.specs import DatasetSpec

    if "locomotion_only" not in available_methods():
        run_snippet(snippet("**Plug-in methods.**", "plugins.md"), "plugins.md", {})
    assert get_method("locomotion_only").description == "the locomotion unchanged"
    with MotionDatabase.open(spliced / "bandai.h5") as db:
        loco, act = db.read(BANDAI[1]), db.read(BANDAI[2])
        spec = DatasetSpec.from_json(db.spec_json(0))
    r = splice(loco, act, spec, method="locomotion_only")
    assert r.motion.name == f"{BANDAI[1]}+{BANDAI[2]}.locomotion_only"
    assert torch.equal(r.motion.rotations, loco.rotations.to(r.motion.rotations.dtype))


def _bash_block(after_heading: str, page: str = "README.md") -> list[list[str]]:
    """The commands of the first ```bash block after ``after_heading`` on ``page`` (continued lines joined)."""
    import shlex

    text = page_path(page).read_text()
    start = text.index(after_heading)
    m = re.search(r"```bash\n(.*?)```", text[start:], re.S)
    assert m, f"no bash block after {after_heading!r}"
    lines = m.group(1).replace("\\\n", " ").splitlines()
    return [shlex.split(ln.split("  #")[0]) for ln in lines if ln.strip()]


def test_the_humanml3d_commands_and_the_loader_snippet_run_as_written(spliced, tmp_path, monkeypatch, capsys):
    """The "Train a text-to-motion model on it" commands on the Bandai Namco splices, then its
    Python snippet reading the folder as MDM does."""
    heading = "# Train a text-to-motion model on it"
    commands = _bash_block(heading, "humanml3d.md")
    assert [c[:2] for c in commands] == [["torchsplice", "export"], ["torchsplice", "export"], ["torchsplice", "import"]]
    shutil.copy(spliced / "spliced.h5", tmp_path / "spliced.h5")
    (tmp_path / "datasets_spec").mkdir()  # the page's commands run from the repository's root
    shutil.copy(REPO / "datasets_spec" / "captions_example.json", tmp_path / "datasets_spec")
    monkeypatch.chdir(tmp_path)
    for c in commands:
        assert main(c[1:] + ["-q"]) == 0, c
    capsys.readouterr()
    from torchsplice.store.database import MotionDatabase

    with MotionDatabase.open(tmp_path / "spliced.h5") as d:
        count = len(d)
    import csv

    rows = list(csv.DictReader(open(tmp_path / "HumanML3D" / "index.csv")))
    assert len(rows) == 2 * count  # each splice and its mirror
    assert (tmp_path / "HumanML3D" / "all.txt").read_text().split() == [r["id"] for r in rows if r["split"]]
    with MotionDatabase.open(tmp_path / "humanml3d.h5") as d:
        assert len(d) == 2 * count and d.skeleton_info(0).spec_name == "smpl22"
    texts = " ".join(p.read_text() for p in (tmp_path / "HumanML3D_windows" / "texts").glob("*.txt"))
    assert "while shuffling along" in texts
    code = snippet(heading, "humanml3d.md")
    scope: dict = {}
    run_snippet(code, "humanml3d.md", scope)
    assert scope["motion"].shape[1] == 263 and len(scope["tokens"].split()) >= 3


def test_the_python_api_snippet_runs_as_written_in_a_fresh_folder(tmp_path, monkeypatch):
    """Every name it uses is defined in it (the built-in sample, no data), and it runs twice."""
    code = snippet("# Python API", "python.md")
    monkeypatch.chdir(tmp_path)
    for _ in range(2):  # a reader who runs it again gets no "already exists"
        scope: dict = {}
        run_snippet(code, "python.md", scope)
    assert scope["result"].motion.num_frames > 0 and len(scope["results"]) == 2
    assert scope["pos"].shape[-1] == 3 and scope["clip"].name == "walk_straight"


def test_the_n_x_m_block_and_the_pipeline_snippet_run_in_order_in_one_folder(spliced, tmp_path, monkeypatch, capsys):
    """The n x m job's commands one after the other, as a reader runs them (each writes its own
    output), then the whole-pipeline snippet in the same folder, twice."""
    import subprocess
    import sys

    shutil.copy(spliced / "bandai.h5", tmp_path / "bandai.h5")
    shutil.copytree(spliced / "bvh", tmp_path / "bvh")
    monkeypatch.chdir(tmp_path)
    commands = _bash_block("# The n x m job", "job.md")
    assert [c[0] for c in commands] == ["torchsplice", "torchsplice", "python"]
    for c in commands:
        if c[0] == "torchsplice":
            assert main(c[1:] + ["-q", "--workers", "1"]) == 0, c
        else:
            script = Path(__file__).resolve().parents[2] / c[1]
            out = subprocess.run([sys.executable, str(script), *c[2:], "-q", "--workers", "1"], capture_output=True,
                                 text=True, timeout=600)
            assert out.returncode == 0, out.stderr
    outputs = [c[c.index("-o") + 1] for c in commands]
    assert len(set(outputs)) == len(outputs) and all((tmp_path / o).is_file() for o in outputs)
    code = snippet("## The whole pipeline from Python", "python.md")
    for _ in range(2):
        scope: dict = {}
        run_snippet(code, "python.md", scope)
        assert scope["summary"].spliced > 0
    capsys.readouterr()


def test_the_readmes_three_commands_and_its_python_give_the_same_database(mocap_dir, tmp_path, monkeypatch, capsys):
    """The README's "Three commands" on a folder of Bandai Namco takes, then "The same in Python"
    in another folder: the same spliced clips bit for bit, the same packed file's frames, and a
    dataset item of the shape the comment says."""
    import h5py
    import numpy as np

    bandai = mocap_dir / "bandai_namco_research_motiondataset"
    commands = _bash_block("## Three commands")
    assert [c[:2] for c in commands] == [["torchsplice", "import"], ["torchsplice", "splice-all"],
                                         ["torchsplice", "export"]]
    code = snippet("## The same in Python")
    assert "from torchsplice import import_bvh, splice_all, export_clips, MotionDataset" in code
    runs = {}
    for how in ("commands", "python"):
        folder = tmp_path / how
        (folder / "path" / "to" / "bvh").mkdir(parents=True)
        for stem in BANDAI + ["dataset-2_wave-right-hand_normal_001"]:
            shutil.copy(bandai / f"{stem}.bvh", folder / "path" / "to" / "bvh")
        monkeypatch.chdir(folder)
        if how == "commands":
            for c in commands:
                extra = ["--workers", "1"] if c[1] == "splice-all" else []
                assert main(c[1:] + ["-q", *extra]) == 0, c
        else:
            scope: dict = {}
            run_snippet(code, "README.md", scope)
            item, ds = scope["item"], scope["ds"]
            assert item["rotations_6d"].shape == (60, 22, 6) and item["trajectory"].shape == (60, 3)
            assert len(ds) > 0 and scope["summary"].spliced > 0
        with h5py.File(folder / "mocap_spliced.h5", "r") as f:
            runs[how] = (list(f["clips/name"].asstr()[()]), f["skeletons/0/rotations"][()])
        with np.load(folder / "mocap_spliced.npz") as z:
            runs[how] += (z["rotations_6d"], z["offsets"])
    capsys.readouterr()
    (names, rot, six, offsets), (names2, rot2, six2, offsets2) = runs["commands"], runs["python"]
    assert names == names2 and len(names) > 0
    assert np.array_equal(rot, rot2) and np.array_equal(six, six2) and np.array_equal(offsets, offsets2)


# --- the README and every page, block by block, as a reader runs them -------------------------

#: the reader's own files, which the pages name but cannot make: Bandai Namco takes (a few of
#: the shared ones, covering every clip the pages name, both of its skeletons, the styles the
#: training snippet filters, actions and locomotions), CMU and LAFAN1 folders, and a captions file
READER_BANDAI = [
    "dataset-1_bye_normal_001", "dataset-1_run_normal_001", "dataset-1_walk_normal_001",
    "dataset-1_walk_old_001", "dataset-1_walk_proud_001", "dataset-1_walk_sad_001",
    "dataset-1_punch_normal_001", "dataset-2_walk_normal_008", "dataset-2_walk-turn-left_normal_025",
    "dataset-2_walk_elderly_006", "dataset-2_wave-right-hand_normal_001",
]
#: the folders of Bandai Namco takes the pages import from
READER_FOLDERS = ("path/to/bvh", "path/to/bandai_namco", "bandai_namco")

#: lines the walkthrough does not run, each with why (every one must still be on a page)
NOT_RUN = {
    "bash scripts/test.sh": "the command running this test",
    "ray start --head --port 6379 --num-cpus 16": "starts a cluster across machines; "
                                                  "the Ray engine is tested in tests/job/test_ray.py",
    "ray start --address HEAD:6379 --num-cpus 16": "joins that cluster",
    "torchsplice splice-all bandai.h5 -o cluster.h5 --engine ray --ray-address HEAD:6379": "needs that cluster",
}


def reading_order() -> list[str]:
    """README.md, then every page of the site in the order of mkdocs.yml's ``nav``."""
    nav = (REPO / "mkdocs.yml").read_text().split("\nnav:", 1)[1]
    pages = re.findall(r"^\s+-\s+(?:[^:\n]+:\s+)?(\S+\.md)\s*$", nav, re.M)
    assert pages and len(pages) == len(set(pages)), pages
    return ["README.md", *pages]


def test_every_page_with_commands_is_in_the_sites_order():
    """The walkthrough's order holds every page of docs/ (a page left out of the nav would not run)."""
    on_disk = {str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md")}
    assert set(reading_order()[1:]) == on_disk


def readme_blocks() -> list[tuple[str, str, str, str]]:
    """Every fenced block of the README and the pages, in reading order: (where, heading, language, text)."""
    blocks = []
    for page in reading_order():
        text, heading = page_path(page).read_text(), ""
        for m in re.finditer(r"^(#+ [^\n]*)$|^```(\w*)\n(.*?)^```$", text, re.M | re.S):
            if m.group(1):
                heading = m.group(1)
            else:
                where = f"{page} line {text.count(chr(10), 0, m.start()) + 1}"
                blocks.append((where, heading, m.group(2), m.group(3)))
    return blocks


def _reader_clone(repo: Path, dest: Path) -> None:
    """The repository's files (tracked, or new and not ignored) in ``dest``, as a git work tree
    whose status shows what running the pages leaves behind; its .venv is the repository's, and
    its compiled kernels are the repository's too (numba's cache files, valid while the source's
    size and time match, which the copies keep), as a reader's clone holds them once set up."""
    import hashlib
    import subprocess

    files = subprocess.run(["git", "-C", str(repo), "ls-files", "-co", "--exclude-standard", "-z"],
                           capture_output=True, check=True).stdout.decode().split("\0")
    for f in filter(None, files):
        if (repo / f).is_file():
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(repo / f, dest / f)
    # numba files a kernel's cache under a folder named by a hash of its source folder's path
    # (numba.core.caching's locator); should that naming change, the clone compiles: slower, as right
    def named(root: Path) -> str:
        return "cpu_" + hashlib.sha1(str((root / "torchsplice" / "cpu").resolve()).encode()).hexdigest()

    for cached in (repo / "torchsplice" / "cpu" / "__pycache__" / "numba").glob(f"*/{named(repo)}/*.nb[ic]"):
        to = dest / cached.relative_to(repo).parent.parent / named(dest) / cached.name
        to.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cached, to)
    subprocess.run(["git", "init", "-q", str(dest)], check=True)
    subprocess.run(["git", "-C", str(dest), "add", "-A"], check=True)
    (dest / ".venv").symlink_to(repo / ".venv")


@pytest.mark.slow
@pytest.mark.timeout(3600)  # a set-up and every block of the site, each up to 900 s
def test_every_readme_block_runs_in_order_in_one_fresh_clone(mocap_dir, tmp_path):
    """A reader's first hour: a fresh copy of the repository, their data beside the commands, and
    every block of the README and then of each page of the site (in the nav's order) run top to
    bottom in that one folder (bash blocks by bash, Python blocks by python, both from the
    repository root), each exiting 0; afterwards nothing they wrote is left untracked in the
    repository (git status), what they wrote is what they name (the outputs .gitignore keeps out
    of commits), and no command left a work file behind."""
    import subprocess
    import sys

    repo = REPO
    if shutil.which("git") is None or not (repo / ".git").exists():
        pytest.skip("needs git and a git checkout (the copy is made from its files)")
    if not (repo / ".venv" / "bin" / "activate").is_file():
        pytest.skip("needs the repository's .venv (bash scripts/setup_env.sh makes it)")
    # the shared .venv brought up to date by the repository itself first: the clone's set-up then finds it
    # current, and never reinstalls the package from the clone (which this test deletes)
    subprocess.run(["bash", "scripts/setup_env.sh"], cwd=repo, check=True, capture_output=True, timeout=1800)
    clone = tmp_path / "torchsplice"
    clone.mkdir()
    _reader_clone(repo, clone)
    bandai = mocap_dir / "bandai_namco_research_motiondataset"
    for folder in READER_FOLDERS:
        (clone / folder).mkdir(parents=True)
        for stem in READER_BANDAI:
            shutil.copy(bandai / f"{stem}.bvh", clone / folder)
    shutil.copytree(mocap_dir / "cmu_graphics_lab", clone / "cmu", ignore=shutil.ignore_patterns("*.md", "LICENSE"))
    shutil.copytree(mocap_dir / "lafan1_via_pypi_bvhtools", clone / "lafan1",
                    ignore=shutil.ignore_patterns("*.md", "LICENSE"))
    (clone / ".git" / "info" / "exclude").write_text("/path/\n/bandai_namco/\n/cmu/\n/lafan1/\n")

    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
               TORCHSPLICE_MOCAP=str(mocap_dir))
    if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0) >= 2:  # the process's share of the cores
        env["NUMBA_NUM_THREADS"] = os.environ["OMP_NUM_THREADS"]  # (tests/conftest.py set it)
    scripts = tmp_path / "blocks"  # outside the clone, so that Python imports the installed package
    scripts.mkdir()
    skipped, ran, done = set(), 0, set()
    for n, (where, heading, lang, text) in enumerate(readme_blocks()):
        if lang in ("", "text"):
            assert not re.search(r"^(torchsplice|python|bash) ", text, re.M), f"{where}: a command block without a language"
            continue  # a listing, an output or an install line, nothing to run
        assert lang in ("bash", "python"), f"{where}: a ```{lang} block the walkthrough cannot run"
        if text in done:  # the same block on another page (docs/setup.md repeats the README's set-up): run once
            continue
        done.add(text)
        kept = []
        for ln in text.splitlines():
            command = ln.split("  #")[0].strip()
            if command in NOT_RUN:
                skipped.add(command)
            else:
                kept.append(ln)
        script = scripts / f"block{n:03d}.{'sh' if lang == 'bash' else 'py'}"
        script.write_text("\n".join(kept) + "\n")
        argv = ["bash", "-eo", "pipefail", str(script)] if lang == "bash" else [sys.executable, str(script)]
        out = subprocess.run(argv, cwd=clone, env=env, capture_output=True, text=True, timeout=900)
        assert out.returncode == 0, (f"{where} ({heading}) exited {out.returncode}:\n"
                                     f"{out.stdout[-2000:]}\n{out.stderr[-3000:]}")
        ran += 1
    assert skipped == set(NOT_RUN), f"lines no longer on any page: {set(NOT_RUN) - skipped}"
    assert ran >= 15
    status = subprocess.run(["git", "-C", str(clone), "status", "--porcelain", "--untracked-files=all"],
                            capture_output=True, text=True, check=True).stdout.splitlines()
    assert [s for s in status if not s.startswith("A ")] == [], "the pages' commands left files in the repository"
    ignored = subprocess.run(["git", "-C", str(clone), "status", "--porcelain", "--ignored"], capture_output=True,
                             text=True, check=True).stdout.splitlines()
    outputs = {ln[3:].rstrip("/") for ln in ignored if ln.startswith("!! ")} - {".venv"}
    outputs = {o for o in outputs if "__pycache__" not in o and not o.endswith(".egg-info")}
    text = "\n".join(page_path(p).read_text() for p in reading_order())
    assert len(outputs) >= 10, outputs  # what the pages wrote, each an output they name (not a work file left over)

    def named(n: str) -> bool:  # the index of a job or a packed export counts as named with its output
        return n in text or (n.endswith(".index.csv") and n[:-10] in text)

    assert not [o for o in outputs if not named(Path(o).name)], "outputs no page names"
    left = [os.path.join(d, n) for d, dirs, files in os.walk(clone) if ".git" not in Path(d).relative_to(clone).parts
            for n in dirs + files if n.startswith(".") and (n.endswith((".parts", ".lock")) or ".partial-" in n)]
    assert left == [], "work files of an unfinished command left behind"


def test_12_the_package_imports_from_the_clones_parent_folder(tmp_path):
    """Run from the folder holding a clone named torchsplice, Python sees that folder as an empty
    namespace package unless the environment puts the repository itself on sys.path (the setup's
    compat editable install); then the real package wins."""
    import subprocess
    import sys

    repo = Path(__file__).resolve().parents[2]
    (tmp_path / "torchsplice").mkdir()  # a clone's folder: no __init__.py at its top
    (tmp_path / "torchsplice" / "README.md").write_text("a clone")
    env = {"PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", "from torchsplice import __version__; import torchsplice; "
                          "print(__version__, torchsplice.__file__)"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[1] == str(repo / "torchsplice" / "__init__.py")


def test_11_the_demo_draws_the_pair_where_the_naive_splice_loses_the_actions_posture_most():
    """The demo's preview pair is, of the sample's 25, the one whose naive and method's splices
    differ most in mean trunk lean, and the figures the README and the docs' home page give for it
    hold (both describe the picture): the box carrier leans
    back about 12 degrees, the method's splice keeps it, the naive one stands at about 5."""
    from tests.splice.test_splice import leans
    from torchsplice.sample import sample_motions
    from torchsplice.specs import load_spec
    from torchsplice.splice import splice

    spec = load_spec("sample")
    clips = {c.name: c for c in sample_motions()}
    roles = spec.bind(clips["jog"].skeleton)
    locomotions = ["walk_straight", "walk_curve", "turn_sharp", "sidestep", "jog"]
    actions = ["carry_box", "carry_cup", "wave", "punch", "arms_out"]
    lean = {}
    for lo in locomotions:
        for ac in actions:
            for method in ("splice", "naive"):
                lean[lo, ac, method] = float(leans(splice(clips[lo], clips[ac], spec, method=method).motion, roles).mean())
    gap = {(lo, ac): abs(lean[lo, ac, "splice"] - lean[lo, ac, "naive"]) for lo in locomotions for ac in actions}
    assert max(gap, key=gap.get) == ("jog", "carry_box")
    action = float(leans(clips["carry_box"], roles).mean())
    assert abs(action + 12) < 1 and abs(lean["jog", "carry_box", "splice"] + 12) < 1  # leans: forward positive
    assert abs(lean["jog", "carry_box", "naive"] + 5) < 1
    demo = (Path(__file__).resolve().parents[2] / "scripts" / "demo.sh").read_text()
    assert "--overlay jog+carry_box jog+carry_box.naive" in demo
    for page in ("README.md", "docs/index.md"):
        text = (Path(__file__).resolve().parents[2] / page).read_text()
        assert "leans back (12 degrees" in text and "stands straighter (5 degrees)" in text, page
