"""The browser viewer (``torchsplice view``): compact positions that decode to the clips, the
clips a page holds (sources and other methods of spliced clips, the --max-clips bound, the
run record's inputs or --sources), a self-contained page, render --sources, and the page in a
real browser (headless chromium through selenium: marker ``browser``). Through the Python API
(:func:`build_viewer`, :func:`write_viewer`, :func:`read_clips`, :func:`splice_all`); the command
line where its words (flags in its notes) and its one-line refusals are the subject."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from cli_helpers import run
from realdata import REPO
from tests.viz.test_render import axes_cycled, ten_seconds

from torchsplice import splice_all
from torchsplice.core.errors import DatabaseError, TorchspliceError
from torchsplice.store.database import MotionDatabase
from torchsplice.sample import sample_motion
from torchsplice.specs import load_spec
from torchsplice.viz.render import render
from torchsplice.viz.sources import read_clips
from torchsplice.viz.viewer import build_viewer, clip_payload, dequantize, quantize, viewer_notes, write_viewer

LOCOS = ["walk_straight", "walk_curve"]
ACTIONS = ["carry_box", "wave"]
METHODS = ["splice", "naive", "cpmc"]


def page_data(html: str) -> dict:
    m = re.search(r'<script id="viewer-data" type="application/json">(.*?)</script>', html, re.S)
    return json.loads(m.group(1))


def decoded(c: dict) -> np.ndarray:
    import base64
    return dequantize(base64.b64decode(c["data"]), c["offset"], c["scale"], c["points"])


@pytest.fixture(scope="module")
def job(sample_db, tmp_path_factory):
    """The sample database and a 2 x 2 job with three methods (12 spliced clips), sources not copied."""
    out = tmp_path_factory.mktemp("view") / "spliced.h5"
    assert splice_all(sample_db, out, locomotions=",".join(LOCOS), actions=",".join(ACTIONS),
                      methods=",".join(METHODS)).spliced == 12
    return sample_db, out


# -- compact positions ---------------------------------------------------------------------------


def test_quantize_round_trip_within_half_a_step():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(40, 7, 3)) * [300.0, 2.0, 50.0] + [1000.0, 0.0, -20.0]
    data, offset, scale = quantize(pts)
    assert len(data) == pts.size * 2  # int16
    back = dequantize(data, offset, scale, 7)
    assert np.all(np.abs(back - pts) <= 0.5 * np.asarray(scale) + 1e-12)
    assert np.allclose(np.asarray(scale) * 65534, np.ptp(pts.reshape(-1, 3), axis=0))  # the whole range, one step each
    flat = quantize(np.full((3, 2, 3), 5.0))  # a constant: exact
    assert np.array_equal(dequantize(flat[0], flat[1], flat[2], 2), np.full((3, 2, 3), 5.0))


def test_payload_is_the_clip_in_metres_y_up_on_the_floor():
    """Bones keep their lengths (cm to m), the floor is at y = 0, and the same clip stored Z up
    gives the same positions."""
    spec = load_spec("sample")
    walk = sample_motion("walk_curve", dtype=torch.float64).slice(0, 60)
    c = clip_payload(walk, spec)
    pts = decoded(c)
    assert pts.shape == (60, c["points"], 3) and c["frames"] == 60 and c["fps"] == 30.0
    step = np.linalg.norm(c["scale"])
    # every bone is as long as the skeleton says, in every frame
    sk = walk.skeleton
    lengths = np.linalg.norm(pts[:, [a for a, _, _ in c["bones"]]] - pts[:, [b for _, b, _ in c["bones"]]], axis=-1)
    assert np.all(lengths.std(axis=0) < 2 * step)  # rigid
    offsets = np.concatenate([sk.offsets[1:].numpy(), sk.end_site_offsets.numpy()]) * 0.01
    known = np.linalg.norm(offsets, axis=-1)
    for L in lengths[0]:
        assert np.min(np.abs(known - L)) < 2 * step  # each bone is one of the skeleton's, in metres
    assert abs(pts[..., 1].min()) < step  # on the floor
    assert 1.3 < pts[..., 1].max() < 2.1  # a person's height in metres, Y up
    sides = {s for _, _, s in c["bones"]}
    assert sides == {0, 1, 2}  # centre, left and right bones
    assert c["head"] == c["points"] - 1 and 0.05 < c["headRadius"] < 0.2
    # the same clip in Z-up axes: the same picture
    z_spec = dataclasses.replace(spec, up_axis="z")
    cz = clip_payload(axes_cycled(walk), z_spec)
    assert cz["bones"] == c["bones"]
    assert np.abs(decoded(cz) - pts).max() < 3 * step


# -- the page's contents ------------------------------------------------------------------------


def test_page_is_self_contained_with_every_clip_and_the_sources(job):
    src, out = job
    html, got = build_viewer(out)
    data = page_data(html)
    names = [c["name"] for c in data["clips"]]
    with MotionDatabase.open(out) as db:
        spliced = db.names
    assert set(spliced) <= set(names) and len(spliced) == 12
    assert set(LOCOS + ACTIONS) <= set(names)  # read from the run record's input
    assert len(names) == len(set(names)) == 16 and got.names == names and not got.cut and not got.missing
    for c in data["clips"]:
        if c["name"] in LOCOS + ACTIONS:
            assert c["db"] == "sample.h5" and c["role"] in ("locomotion", "action")
        else:
            assert c["role"] == "spliced" and c["columns"]["method"] in METHODS and c["db"] == ""
            assert c["columns"]["locomotion"] in LOCOS and c["columns"]["action"] in ACTIONS
    # every group: a spliced clip's locomotion and action follow it, then the other methods
    first = names.index("walk_straight+carry_box")
    assert names[first + 1:first + 3] == ["walk_straight", "carry_box"]
    # self-contained: no external script, stylesheet or fetch; three.js and OrbitControls inlined
    assert not re.search(r"<script[^>]+src=|<link\b|fetch\(", html)
    imports = json.loads(re.search(r'<script type="importmap">(.*?)</script>', html, re.S).group(1))["imports"]
    assert set(imports) == {"three", "three-core", "three/addons/controls/OrbitControls.js"}
    assert all(u.startswith("data:text/javascript;base64,") for u in imports.values())
    assert got.size == len(html.encode()) < 3_000_000


def test_named_clips_bring_their_group_and_the_bound_cuts(job, tmp_path, capsys):
    src, out = job
    html, got = build_viewer(out, clips=["walk_curve+wave.naive"])
    assert got.names == ["walk_curve+wave.naive", "walk_curve", "wave", "walk_curve+wave", "walk_curve+wave.cpmc"]
    _, got = build_viewer(out, max_clips=5)
    assert len(got.names) == 5 and got.cut
    got = write_viewer(out, tmp_path / "v.html", max_clips=4)
    err = capsys.readouterr().err
    assert len(got.names) == 4 and got.cut and len(page_data((tmp_path / "v.html").read_text())["clips"]) == 4
    assert "max_clips 4" in err and "of the 12" in err and err == "".join(ln + "\n" for ln in viewer_notes(got, out, 4))
    with pytest.raises(TorchspliceError, match="no clip named 'nope'"):
        build_viewer(out, clips=["nope"])


def test_the_view_command_says_its_notes_with_its_flags(job, tmp_path, capsys):
    src, out = job
    code, msg, err = run(capsys, "view", out, "-o", tmp_path / "v.html", "--max-clips", "4")
    assert code == 0 and "wrote" in msg and "4 clips" in msg
    assert "--max-clips 4" in err and "of the 12" in err
    code, _, err = run(capsys, "view", _moved(job, tmp_path), "-o", tmp_path / "a.html")
    assert code == 0 and "4 source clips are in no database" in err and "--sources" in err


def _moved(job, tmp_path) -> Path:
    """A copy of the job's output whose run record names an input that no longer exists."""
    import h5py

    src, out = job
    moved_out = tmp_path / "spliced.h5"
    shutil.copy(out, moved_out)
    with h5py.File(moved_out, "r+") as f:
        rec = json.loads(f.attrs["run"])
        rec["database"]["path"] = str(tmp_path / "gone.h5")
        f.attrs["run"] = json.dumps(rec)
    return moved_out


def test_sources_from_another_place(job, tmp_path, capsys):
    """The run record's input moved away: the page says which sources it lacks; --sources finds them."""
    src, out = job
    with MotionDatabase.open(out) as db:
        run_rec = json.loads(db.attrs["run"])
    assert run_rec["database"]["path"] == str(src.resolve())
    moved_out = _moved(job, tmp_path)  # a run record naming a file that no longer exists
    away = tmp_path / "elsewhere.h5"
    shutil.copy(src, away)
    got = write_viewer(moved_out, tmp_path / "a.html")
    err = capsys.readouterr().err
    assert "4 source clips are in no database" in err and "sources" in err
    assert sorted(got.missing) == sorted(LOCOS + ACTIONS)
    assert sorted(page_data((tmp_path / "a.html").read_text())["missing"]) == sorted(LOCOS + ACTIONS)
    got = write_viewer(moved_out, tmp_path / "b.html", sources=[away])
    assert capsys.readouterr().err == "" and not got.missing
    data = page_data((tmp_path / "b.html").read_text())
    assert {c["name"] for c in data["clips"] if c["db"] == "elsewhere.h5"} == set(LOCOS + ACTIONS)
    # render takes the same sources: a spliced clip beside its locomotion and action
    clips, spec = read_clips(moved_out, ["walk_curve", "wave", "walk_curve+wave"], sources=[away])
    assert [c.name for c in clips] == ["walk_curve", "wave", "walk_curve+wave"]
    render(clips, tmp_path / "r.png", up_axis=spec.up_axis, frames=2)
    assert (tmp_path / "r.png").exists()
    with pytest.raises(DatabaseError, match="no clip named 'walk_curve'") as exc:
        read_clips(moved_out, ["walk_curve"])
    assert "\n" not in str(exc.value)


def test_view_command_errors_are_one_line(job, tmp_path, capsys):
    src, out = job
    (tmp_path / "v.html").write_text("old")
    code, _, err = run(capsys, "view", out, "-o", tmp_path / "v.html")
    assert code == 2 and "already exists" in err and err.count("\n") == 1
    assert (tmp_path / "v.html").read_text() == "old"
    code, _, err = run(capsys, "view", out, "-o", tmp_path / "v.png")
    assert code == 2 and ".html" in err and err.count("\n") == 1
    code, _, err = run(capsys, "view", out, "missing_clip", "-o", tmp_path / "w.html")
    assert code == 2 and "missing_clip" in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.html"]


def test_a_hundred_ten_second_clips_fit_in_10_mb(tmp_path):
    spec = load_spec("sample")
    base = [ten_seconds(n) for n in ("walk_straight", "walk_curve", "carry_box", "jog")]
    path = tmp_path / "hundred.h5"
    with MotionDatabase.create(path) as db:
        for k in range(120):
            db.append(dataclasses.replace(base[k % 4], name=f"clip_{k:03d}"), spec=spec)
    out = tmp_path / "v.html"
    got = write_viewer(path, out, quiet=True)
    assert len(got.names) == 100 and got.cut  # the default bound
    assert out.stat().st_size < 10_000_000


# -- in a real browser --------------------------------------------------------------------------


def _browser_or_skip():
    """Paths of Debian's chromium and chromedriver and selenium, else skip (fail under CI=true)."""
    reason = None
    try:
        import selenium  # noqa: F401
    except ImportError:
        reason = "selenium is not installed (pip install 'torchsplice[test]')"
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver") or next((p for p in ("/usr/lib/chromium/chromedriver",) if os.path.exists(p)), None)
    if reason is None and not (chromium and driver):
        reason = "chromium and chromedriver are not installed (apt-get install chromium chromium-driver)"
    if reason:
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail(reason + "; CI must run the browser tests", pytrace=False)
        pytest.skip(reason)
    return chromium, driver


def test_missing_browser_skips_but_fails_under_ci(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setattr(os.path, "exists", lambda p: False)
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="chromium and chromedriver are not installed"):
        _browser_or_skip()
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI must run the browser tests"):
        _browser_or_skip()


@pytest.fixture(scope="module")
def browser():
    chromium, driver_path = _browser_or_skip()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1280,800",
              "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-gpu", "--hide-scrollbars",
              "--force-device-scale-factor=1"):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    d = webdriver.Chrome(service=Service(driver_path), options=opts)
    d.set_page_load_timeout(60)
    yield d
    d.quit()


def _shot(d) -> np.ndarray:
    from PIL import Image
    return np.asarray(Image.open(io.BytesIO(d.get_screenshot_as_png())).convert("RGB"), dtype=np.int16)


def _canvas(d, rgb: np.ndarray) -> np.ndarray:
    r = d.execute_script("const b = document.querySelector('#stage canvas').getBoundingClientRect();"
                         "return [b.left, b.top, b.width, b.height];")
    x, y, w, h = (int(round(v)) for v in r)
    return rgb[y:y + h, x:x + w]


def _settle(d):
    """Two animation frames, so what was drawn is on the screen."""
    d.execute_async_script("const done = arguments[0]; requestAnimationFrame(() => requestAnimationFrame(done));")


@pytest.mark.browser
@pytest.mark.slow
def test_viewer_in_chromium(job, tmp_path, browser):
    """The page opens without console errors, draws the clips (not a blank canvas), scrubbing
    changes the picture, the picker lists the database's clips and filters them, and one click
    on a spliced clip shows it with its locomotion, action and the other methods in sync."""
    from selenium.webdriver.common.by import By

    src, out = job
    page = tmp_path / "viewer.html"
    write_viewer(out, page, quiet=True)
    d = browser
    d.get(page.as_uri())
    for _ in range(200):
        if d.execute_script("return !!(window.torchspliceViewer && window.torchspliceViewer.ready)"):
            break
        time.sleep(0.05)
    else:
        pytest.fail(f"the viewer did not start; console: {d.get_log('browser')}")
    v = "window.torchspliceViewer"
    with MotionDatabase.open(out) as db:
        spliced = db.names
    # the picker lists every clip of the database (and the sources beside them)
    rows = [e.get_attribute("data-name") for e in d.find_elements(By.CSS_SELECTOR, "#list .clip-row")]
    assert set(spliced) <= set(rows) and set(LOCOS + ACTIONS) <= set(rows) and len(rows) == 16
    # filtered by method and by role
    d.execute_script("const s = document.getElementById('f-method'); s.value = 'naive'; s.dispatchEvent(new Event('change'));")
    rows = [e.get_attribute("data-name") for e in d.find_elements(By.CSS_SELECTOR, "#list .clip-row")]
    assert sorted(rows) == sorted(n for n in spliced if n.endswith(".naive"))
    d.execute_script("const s = document.getElementById('f-method'); s.value = ''; s.dispatchEvent(new Event('change'));"
                     "const r = document.getElementById('f-role'); r.value = 'locomotion'; r.dispatchEvent(new Event('change'));")
    rows = [e.get_attribute("data-name") for e in d.find_elements(By.CSS_SELECTOR, "#list .clip-row")]
    assert sorted(rows) == sorted(LOCOS)
    d.execute_script("const r = document.getElementById('f-role'); r.value = ''; r.dispatchEvent(new Event('change'));")
    # one click on a spliced clip: its locomotion, its action and every method's result
    d.find_element(By.CSS_SELECTOR, '#list .clip-row[data-name="walk_curve+carry_box"]').click()
    shown = d.execute_script(f"return {v}.shown()")
    assert shown == ["walk_curve", "carry_box", "walk_curve+carry_box", "walk_curve+carry_box.naive",
                     "walk_curve+carry_box.cpmc"]
    # scrub with the timeline: pauses, and every panel shows its own frame of the same time
    d.execute_script("const s = document.getElementById('scrub'); s.value = '0'; s.dispatchEvent(new Event('input'));")
    _settle(d)
    assert d.execute_script(f"return {v}.frames()") == [0] * 5
    assert d.find_element(By.ID, "play").text == "Play"  # scrubbing paused it
    a = _canvas(d, _shot(d))
    assert a.std() > 12  # not blank: figures, grid, floor
    blue = (a[..., 2] > 140) & (a[..., 0] < 90)
    red = (a[..., 0] > 160) & (a[..., 2] < 90)
    assert blue.mean() > 0.0005 and red.mean() > 0.0005  # left and right bones in their colours
    d.execute_script("const s = document.getElementById('scrub'); s.value = '45'; s.dispatchEvent(new Event('input'));")
    _settle(d)
    assert d.execute_script(f"return {v}.frames()") == [45] * 5  # 1.5 s at 30 fps in every clip
    b = _canvas(d, _shot(d))
    assert a.shape == b.shape and np.abs(a - b).mean() > 0.5  # the figures moved
    clock = d.find_element(By.ID, "clock").text
    assert "1.50 s" in clock and "frame 45" in clock
    labels = [e.text for e in d.find_elements(By.CSS_SELECTOR, "#labels .plabel") if e.is_displayed()]
    assert len(labels) == 5 and all("frame 45 /" in t for t in labels)
    # the legend names the sides' colours
    assert "left" in d.find_element(By.ID, "legend").text and "right" in d.find_element(By.ID, "legend").text
    # play resumes
    d.find_element(By.ID, "play").click()
    time.sleep(0.5)
    assert d.execute_script(f"return {v}.frames()")[0] != 45
    severe = [e for e in d.get_log("browser") if e["level"] == "SEVERE"]
    assert severe == [], severe
    # the picture of docs/viewer.md, refreshed only on request
    d.execute_script(f"{v}.setPlaying(false); {v}.setTime(1.5);")
    _settle(d)
    shot = tmp_path / "viewer.png"
    d.save_screenshot(str(shot))
    if os.environ.get("TORCHSPLICE_UPDATE_PICTURES") == "1":  # 256 colours keep the file small
        from PIL import Image
        with Image.open(shot) as im:
            im.convert("RGB").quantize(colors=256, dither=Image.Dither.NONE).save(
                REPO / "torchsplice" / "viz" / "viewer.png", optimize=True)
