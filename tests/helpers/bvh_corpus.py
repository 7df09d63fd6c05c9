"""A corpus of malformed and edge-case BVH files, made at test time from real ones.

:func:`build_corpus` reads a few small real files (a Bandai Namco, a CMU and a LAFAN1 clip
from the shared mocap folder, see ``conftest.py``), keeps their first 20 frames, and derives
well over a thousand variants from them: truncations at many points, wrong counts, non-finite
and absurd numbers, bad tokens, non-UTF-8 bytes, a byte order mark, CRLF, tabs, trailing
lines, missing braces, duplicate names, deep and wide hierarchies, empty files and more. It
is deterministic (seeded): the same folder gives the same corpus.

Each :class:`Variant` carries its expectation:

- ``parses``: ``read_bvh`` must return a clip (``True``) or raise a ``TorchspliceError`` with a
  clean one-line message (``False``);
- ``imports``: at the command line (``torchsplice import``), the file must be imported
  (``True``), skipped with one ``skipped FILE: reason`` line (``False``), or either, cleanly
  (``None``: e.g. a valid file whose skeleton no dataset spec fits);
- for a valid one, ``ref`` names the clean parse it must equal (``Corpus.refs``: joint names,
  frame count, fps and values), ``frames``/``fps`` what differs from it, ``warns`` whether a
  ``BVHWarning`` is expected;
- for an invalid one, optionally ``phrase``: a few words its message must hold.
"""

from __future__ import annotations

import random
import re
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Variant", "Corpus", "build_corpus", "SOURCES", "N_FRAMES"]

N_FRAMES = 20  # frames kept from each real file, so that the corpus stays small and fast
SOURCES = {  # short key: file under the mocap folder (small files; see each folder's README.md)
    "bn": "bandai_namco_research_motiondataset/dataset-1_dash_normal_001.bvh",  # 20 frames, 30 fps
    "cmu": "cmu_graphics_lab/cmu_12_01_walk.bvh",  # 524 frames, 120 fps, mixed CRLF/LF
    "lafan": "lafan1_via_pypi_bvhtools/test2.bvh",  # 3,945 frames, 30 fps, CRLF
}


@dataclass(frozen=True)
class Variant:
    """One corpus file and what reading and importing it must give (see the module docstring)."""

    stem: str
    data: bytes
    parses: bool
    imports: bool | None
    what: str
    ref: str | None = None
    frames: int | None = None
    fps: float | None = None
    warns: bool = False
    same_names: bool = True
    phrase: str | None = None

    @property
    def name(self) -> str:
        return self.stem + ".bvh"


@dataclass
class Corpus:
    variants: list[Variant] = field(default_factory=list)
    refs: dict[str, str] = field(default_factory=dict)  # key -> clean BVH text of the reference clip

    def write(self, folder: Path, variants=None) -> list[Path]:
        """Write ``variants`` (all by default) into ``folder``; their paths, in order."""
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for v in self.variants if variants is None else variants:
            p = folder / v.name
            p.write_bytes(v.data)
            paths.append(p)
        return paths


# --------------------------------------------------------------------------------------------
# the real sources, cut to their first frames
# --------------------------------------------------------------------------------------------
def _head_lines(path: Path, n_frames: int) -> list[str]:
    """The file's lines (line ends dropped) up to and including its first ``n_frames`` frames,
    with the Frames: line saying ``n_frames``; the rest of the file is not read."""
    lines: list[str] = []
    seen_motion, data = False, 0
    with open(path, "rb") as fh:
        for raw in fh:
            line = raw.decode("utf-8").rstrip("\r\n")
            if seen_motion and line.strip().lower().startswith("frames"):
                key, _, value = line.partition(":")
                ws = re.match(r"\s*", value).group(0) or " "
                line = f"{key}:{ws}{n_frames}"
            elif seen_motion and not line.strip().lower().startswith("frame time") and line.strip():
                data += 1
            lines.append(line)
            seen_motion = seen_motion or line.strip().upper() == "MOTION"
            if data == n_frames:
                break
    return lines


class _Base:
    """One real file's first frames as LF text, with the line numbers of its parts (0-based)."""

    def __init__(self, key: str, lines: list[str]):
        self.key, self.lines = key, lines
        self.motion = next(i for i, l in enumerate(lines) if l.strip().upper() == "MOTION")
        self.frames_line, self.time_line, self.first = self.motion + 1, self.motion + 2, self.motion + 3
        self.n = len(lines) - self.first
        hier = range(self.motion)
        first_tok = [l.split()[0] if l.split() else "" for l in lines]
        self.joint_lines = [i for i in hier if first_tok[i] in ("ROOT", "JOINT")]
        self.channel_lines = [i for i in hier if first_tok[i] == "CHANNELS"]
        self.offset_lines = [i for i in hier if first_tok[i] == "OFFSET"]
        self.end_offset_lines = [i for i in self.offset_lines if lines[i - 2].split()[:1] == ["End"]]
        self.open_lines = [i for i in hier if lines[i].strip() == "{"]
        self.close_lines = [i for i in hier if lines[i].strip() == "}"]
        self.names = [" ".join(lines[i].split()[1:]) for i in self.joint_lines]
        self.n_channels = sum(int(lines[i].split()[1]) for i in self.channel_lines)

    def text(self, lines=None) -> str:
        return "\n".join(self.lines if lines is None else lines) + "\n"

    def copy(self) -> list[str]:
        return list(self.lines)

    def replace_token(self, line: int, col: int, token: str) -> list[str]:
        out = self.copy()
        parts = out[line].split()
        indent = re.match(r"\s*", out[line]).group(0)
        parts[col] = token
        out[line] = indent + " ".join(parts)
        return out


# --------------------------------------------------------------------------------------------
# the corpus
# --------------------------------------------------------------------------------------------
BAD_NUMBERS = ["abc", "1,5", "0x10", "1_000", "\u0661", "\u00b2", "\uff13", "--1", "1e", ".", "+", "1.2.3",
               "\u00bd", "1e5x", "#"]
NON_FINITE = ["nan", "NaN", "inf", "-inf", "Infinity", "1e999", "-1e400"]
ABSURD = ["1e300", "-1e13", "123456789012345678"]
BAD_COUNTS = ["\u00b2", "\u0663", "\uff13", "-3", "3.0", "three", "99999999999999999999", "10"]
BAD_FRAME_TIMES = ["5e-324", "0", "-0.0333333", "2", "1e9", "0.0001", "nan", "inf", "0,0333333", "1/30",
                   "\u0660.\u0660\u0663", "fast"]
CONTROL = ["\x00", "\x01", "\x07", "\x1b", "\x7f", "\x08"]


def build_corpus(mocap: Path, seed: int = 0, n_frames: int = N_FRAMES) -> Corpus:
    """The corpus made from the real files under ``mocap`` (deterministic for one ``seed``)."""
    rng = random.Random(seed)
    corpus = Corpus()
    seen: set[str] = set()

    def add(stem, data, parses, imports=None, what="", **kw):
        stem = re.sub(r"[^A-Za-z0-9_-]+", "-", stem)
        assert stem not in seen, stem
        seen.add(stem)
        if isinstance(data, list):
            data = "\n".join(data) + "\n"
        if isinstance(data, str):
            data = data.encode("utf-8")
        if not parses:
            imports = False
        corpus.variants.append(Variant(stem, data, parses, imports, what or stem, **kw))

    for key, rel in SOURCES.items():
        b = _Base(key, _head_lines(mocap / rel, n_frames))
        assert b.n == n_frames, (rel, b.n)
        corpus.refs[key] = b.text()
        _variants_of(b, rng, add)
    _synthetic(rng, add)
    return corpus


def _variants_of(b: _Base, rng: random.Random, add) -> None:
    k = b.key
    text = b.text()
    raw = text.encode("utf-8")
    ok = dict(ref=k)

    def valid(stem, data, imports=True, **kw):
        add(f"{k}_{stem}", data, True, imports, **{**ok, **kw})

    def invalid(stem, data, phrase=None):
        add(f"{k}_{stem}", data, False, False, phrase=phrase)

    # --- the clean file and harmless re-spellings ---------------------------------------------
    valid("clean", text)
    valid("bom", b"\xef\xbb\xbf" + raw)
    valid("crlf", text.replace("\n", "\r\n"))
    valid("cr", text.replace("\n", "\r"))
    valid("mixed_line_ends", "".join(l + ("\r\n" if i % 3 else "\n") for i, l in enumerate(b.lines)))
    valid("no_final_newline", text[:-1])
    valid("bom_crlf", b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode())
    valid("utf16", ("\ufeff" + text).encode("utf-16-le"))
    valid("latin1_whole", text.encode("latin-1"))
    tabs = [re.match(r"\s*", l).group(0).replace("  ", "\t") + "\t".join(l.split()) for l in b.lines]
    tabs[b.time_line] = "Frame\tTime:\t" + b.lines[b.time_line].split(":")[1].strip()
    valid("tabs", tabs)
    spaces = ["   " + "    ".join(l.split()) + "  " for l in b.lines]
    spaces[b.time_line] = "  Frame   Time:    " + b.lines[b.time_line].split(":")[1].strip()
    spaces[b.frames_line] = "Frames   :   " + str(b.n)
    valid("spaces", spaces)
    valid("trailing_ws", [l + " \t " for l in b.lines])
    valid("blank_lines", [x for l in b.lines for x in (l, "")])
    valid("blank_lines_ws", [x for l in b.lines for x in (l, " \t")])
    ft = b.lines[b.time_line].split(":")[1].strip()
    for i, line in enumerate(["Frame\tTime: " + ft, "Frame  Time: " + ft, "Frame Time:" + ft, "FRAME TIME: " + ft,
                              "frame time:\t\t" + ft, " Frame \t Time : " + ft]):
        valid(f"frame_time_ws{i}", b.lines[: b.time_line] + [line] + b.lines[b.time_line + 1:])
    for i, line in enumerate([f"Frames:\t{b.n}", f"Frames:  {b.n}", f"Frames:{b.n}", f"FRAMES: {b.n}",
                              f"Frames : {b.n}", f"Frames: 0{b.n}"]):
        valid(f"frames_ws{i}", b.lines[: b.frames_line] + [line] + b.lines[b.frames_line + 1:])
    low = b.copy()
    low[0], low[b.motion] = "hierarchy", "motion"
    valid("lowercase_keywords", low)
    lc = b.copy()
    for i in b.channel_lines:
        lc[i] = lc[i].lower()
    valid("lowercase_channels", lc)
    es = [re.sub(r"End Site", "End site", l) for l in b.lines]
    valid("end_site_case", es)
    brace = b.copy()
    for i in reversed(b.open_lines):
        if brace[i - 1].split()[:1] in (["ROOT"], ["JOINT"]):
            brace[i - 1] = brace[i - 1] + " {"
            del brace[i]
    valid("brace_on_name_line", brace)
    valid("hierarchy_on_one_line", [" ".join(" ".join(b.lines[: b.motion]).split())] + b.lines[b.motion:])
    # numbers spelt differently (same values)
    for j, (r, spell) in enumerate([(2, lambda t: "+" + t if t[0] != "-" else t), (5, lambda t: t + "0"),
                                    (9, lambda t: t + "e0"), (12, lambda t: t + "E+00"),
                                    (15, lambda t: ("-" if t[0] == "-" else "") + "0" + t.lstrip("-+"))]):
        line = b.first + r
        col = rng.randrange(len(b.lines[line].split()))
        tok = b.lines[line].split()[col]
        valid(f"number_spelling{j}", b.replace_token(line, col, spell(tok)))
    # fewer frames than the file holds: the first ones, with or without the rest as trailing lines
    for m in sorted(set(rng.sample(range(1, b.n), 4)) | {1, b.n - 1}):
        frames_line = f"Frames: {m}"
        head = b.lines[: b.frames_line] + [frames_line]
        valid(f"cut_to_{m}", head + b.lines[b.frames_line + 1: b.first + m], frames=m)
        valid(f"declared_{m}_of_{b.n}", b.lines[: b.frames_line] + [frames_line] + b.lines[b.frames_line + 1:],
              frames=m, warns=True)
    # trailing lines after the declared frames (QAvimator/Second Life keyframe indices, junk)
    for j, tail in enumerate([["1 5 10 20"], ["0", "3", "7", "19"], ["junk here", "", "more junk \x00"],
                              ["", "", "12"], [" ".join(["0"] * b.n_channels)], ["MOTION", "Frames: 3"]]):
        valid(f"trailing{j}", b.lines + tail, warns=bool([t for t in tail if t.strip()]))
    # frame rate edges that are allowed
    for j, (t, fps) in enumerate([("0.001", 1000.0), ("1", 1.0), ("1.0", 1.0), ("0.5", 2.0)]):
        valid(f"frame_time_edge{j}", b.lines[: b.time_line] + [f"Frame Time: {t}"] + b.lines[b.time_line + 1:],
              imports=None, fps=fps)
    # joint names spelt with non-ASCII letters: read (other names), imported if a spec still fits
    j = rng.randrange(1, len(b.joint_lines))
    for i, (enc, new) in enumerate([("utf-8", "Gelenk_\u00fc\u00df"), ("latin-1", "H\u00fcfte"),
                                    ("utf-8", "\u95a2\u7bc0"), ("utf-8", "Two  Words\there")]):
        lines = b.copy()
        lines[b.joint_lines[j]] = re.sub(r"(JOINT\s+).*", lambda mm: mm.group(1) + new, lines[b.joint_lines[j]])
        valid(f"renamed{i}", b.text(lines).encode(enc), imports=None, same_names=False)

    # --- truncations --------------------------------------------------------------------------
    last_line_start = len(raw) - len(b.lines[-1].encode()) - 1
    marks = [0, 1, 4, 9, 10, raw.index(b"ROOT"), raw.index(b"MOTION"), raw.index(b"MOTION") + 3,
             raw.index(b"Frames"), raw.index(b"Frame Time") if b"Frame Time" in raw else 0,
             len(b.text(b.lines[: b.first]).encode()), last_line_start, last_line_start - 1]
    cuts = sorted(set(marks + rng.sample(range(last_line_start), 100)))
    for c in cuts:
        invalid(f"truncated_at_{c}", raw[:c])
    last = b.lines[-1].split()
    invalid("last_frame_cut", b.lines[:-1] + [" ".join(last[: len(last) // 2])], phrase="truncated")
    invalid("last_frame_missing", b.lines[:-1], phrase="truncated")
    invalid("header_only", b.lines[: b.first], phrase="truncated")
    invalid("hierarchy_only", b.lines[: b.motion], phrase="missing motion")
    invalid("motion_only", b.lines[b.motion:], phrase="hierarchy")
    invalid("no_frame_time", b.lines[: b.time_line] + b.lines[b.first:], phrase="frame time")
    invalid("no_frames_line", b.lines[: b.frames_line] + b.lines[b.time_line:], phrase="frames")
    r = rng.randrange(1, b.n - 1)
    invalid("frame_line_deleted", b.lines[: b.first + r] + b.lines[b.first + r + 1:], phrase="truncated")

    # --- wrong counts -------------------------------------------------------------------------
    for m in [b.n + 1, b.n + 5, 1000, 99999999999]:
        invalid(f"frames_{m}", b.lines[: b.frames_line] + [f"Frames: {m}"] + b.lines[b.frames_line + 1:],
                phrase="truncated")
    for j, bad in enumerate(["0", "-1", "20.0", "twenty", "\u00b2\u2070", "\u0662\u0660", "", "9" * 50,
                             "20 frames", "0x14"]):
        invalid(f"frames_bad{j}", b.lines[: b.frames_line] + [f"Frames: {bad}"] + b.lines[b.frames_line + 1:],
                phrase="frame")
    picks = sorted(set([b.channel_lines[0], b.channel_lines[-1]] + rng.sample(b.channel_lines, 3)))
    for i in picks:
        n = int(b.lines[i].split()[1])
        for m in sorted({n - 1, n + 1, 0, 9, n - 3 if n > 3 else 1}):
            invalid(f"channels_{i}_{m}", b.replace_token(i, 1, str(m)))
        for j, bad in enumerate(BAD_COUNTS):
            invalid(f"channels_{i}_bad{j}", b.replace_token(i, 1, bad), phrase="channel")
        names = b.lines[i].split()[2:]
        drop = rng.randrange(len(names))
        lines = b.copy()
        kept = names[:drop] + names[drop + 1:]
        lines[i] = re.match(r"\s*", lines[i]).group(0) + " ".join(["CHANNELS", str(n - 1)] + kept)
        invalid(f"channels_{i}_dropped", lines)
        lines = b.copy()
        extra = next(c for c in ("Xposition", "Yposition", "Zposition", "Xscale") if c not in names)
        lines[i] = re.match(r"\s*", lines[i]).group(0) + " ".join(["CHANNELS", str(n + 1)] + names + [extra])
        invalid(f"channels_{i}_added", lines, phrase="values")
        invalid(f"channels_{i}_badname", b.replace_token(i, 2, "Wrotation"), phrase="channel")
        invalid(f"channels_{i}_repeated", b.replace_token(i, 3, names[0]), phrase="repeated")

    # --- numbers ------------------------------------------------------------------------------
    for rows, tokens, tag, phrase in ((2, BAD_NUMBERS, "bad", "non-numeric"),
                                      (2, NON_FINITE, "nonfinite", "non-finite"), (2, ABSURD, "absurd", "absurd")):
        for j, tok in enumerate(tokens):
            for r in sorted(rng.sample(range(b.n), rows)):
                col = rng.randrange(b.n_channels)
                invalid(f"value_{tag}{j}_f{r}_c{col}", b.replace_token(b.first + r, col, tok), phrase=phrase)
    for tokens, tag in ((BAD_NUMBERS, "bad"), (NON_FINITE, "nonfinite"), (ABSURD, "absurd")):
        for j, tok in enumerate(tokens):
            i = rng.choice(b.offset_lines)
            invalid(f"offset_{tag}{j}_l{i}", b.replace_token(i, 1 + rng.randrange(3), tok), phrase="offset")
    for j, tok in enumerate(NON_FINITE[:4] + ABSURD[:1]):
        i = rng.choice(b.end_offset_lines)
        invalid(f"end_offset_{j}_l{i}", b.replace_token(i, 1 + rng.randrange(3), tok), phrase="end site offset")
    for j, bad in enumerate(BAD_FRAME_TIMES):
        invalid(f"frame_time_bad{j}", b.lines[: b.time_line] + [f"Frame Time: {bad}"] + b.lines[b.time_line + 1:],
                phrase="frame time")
    i = rng.choice(b.offset_lines)
    invalid("offset_two_values", b.copy()[:i] + [" ".join(b.lines[i].split()[:3])] + b.lines[i + 1:])
    invalid("offset_four_values", b.copy()[:i] + [b.lines[i] + " 0"] + b.lines[i + 1:])
    invalid("offset_missing", b.lines[:i] + b.lines[i + 1:])

    # --- bad tokens and bytes -----------------------------------------------------------------
    big = "x" * 100_000
    invalid("huge_token_offset", b.replace_token(b.offset_lines[1], 2, big), phrase="non-numeric")
    invalid("huge_token_frame", b.replace_token(b.first + 3, 4, big), phrase="non-numeric")
    invalid("huge_token_channel", b.replace_token(b.channel_lines[1], 2, big), phrase="channel")
    invalid("huge_frames", b.lines[: b.frames_line] + ["Frames: " + "7" * 100_000] + b.lines[b.frames_line + 1:])
    invalid("huge_frame_time", b.lines[: b.time_line] + ["Frame Time: " + "0" * 100_000] + b.lines[b.time_line + 1:])
    invalid("huge_keyword", b.lines[:3] + [big] + b.lines[3:])
    invalid("huge_junk_line", b.lines[: b.first + 4] + [big] + b.lines[b.first + 5:])
    for j, c in enumerate(CONTROL):
        i = b.joint_lines[rng.randrange(len(b.joint_lines))]
        lines = b.copy()
        lines[i] = lines[i] + c + "x"
        invalid(f"name_control{j}_l{i}", lines, phrase="control character")
    lines = b.copy()
    lines[b.joint_lines[1]] = lines[b.joint_lines[1]] + "\x00" * 100_000
    invalid("name_many_nuls", lines, phrase="control character")
    for j, (pos, junk) in enumerate([("frame", b"\xff"), ("frame", b"\x80\x81"), ("frame", b"\x00"),
                                     ("offset", b"\xfe"), ("start", b"\x00"), ("start", b"\xff\xfe"),
                                     ("keyword", b"\xc3\x28"), ("channels", b"\xe9")]):
        if pos == "frame":
            line = b.first + rng.randrange(b.n)
        elif pos == "offset":
            line = rng.choice(b.offset_lines)
        elif pos == "channels":
            line = rng.choice(b.channel_lines)
        elif pos == "keyword":
            line = b.motion
        else:
            line = 0
        pieces = [l.encode() for l in b.lines]
        cut = pieces[line]
        at = len(cut) if pos in ("frame", "offset", "channels", "keyword") else 0
        if pos in ("offset", "channels", "frame"):  # glue the junk to a token
            at = cut.rindex(b" ") + 2 if b" " in cut.strip() else len(cut)
        pieces[line] = cut[:at] + junk + cut[at:]
        invalid(f"bytes{j}_{pos}", b"\n".join(pieces) + b"\n")
    invalid("utf16_no_bom", text.encode("utf-16-le"))
    invalid("binary_prefix", bytes(rng.randrange(256) for _ in range(64)) + raw)

    # --- braces and structure -----------------------------------------------------------------
    for i in sorted(set(rng.sample(b.open_lines, 6) + [b.open_lines[0], b.open_lines[-1]])):
        invalid(f"open_brace_missing_l{i}", b.lines[:i] + b.lines[i + 1:])
    for i in sorted(set(rng.sample(b.close_lines, 6) + [b.close_lines[0], b.close_lines[-1]])):
        invalid(f"close_brace_missing_l{i}", b.lines[:i] + b.lines[i + 1:])
    for i in sorted(rng.sample(b.close_lines, 3)):
        invalid(f"close_brace_extra_l{i}", b.lines[:i] + ["}"] + b.lines[i:])
        invalid(f"open_brace_extra_l{i}", b.lines[:i] + ["{"] + b.lines[i:])
    for n_dup in range(4):
        a, c = sorted(rng.sample(range(len(b.joint_lines)), 2))
        lines = b.copy()
        lines[b.joint_lines[c]] = re.sub(r"(JOINT\s+).*", lambda mm: mm.group(1) + b.names[a], lines[b.joint_lines[c]])
        invalid(f"duplicate_name{n_dup}_{a}_{c}", lines, phrase="twice")
    lines = b.copy()
    lines[b.joint_lines[2]] = lines[b.joint_lines[2]].split()[0]
    invalid("joint_without_name", lines, phrase="without a name")
    invalid("two_roots", b.lines[: b.motion] + b.lines[1: b.motion] + b.lines[b.motion:], phrase="root")
    invalid("no_root", [b.lines[0]] + b.lines[2:], phrase="root")
    invalid("hierarchy_misspelt", ["HIERARCHIE"] + b.lines[1:], phrase="hierarchy")
    invalid("motion_first", b.lines[b.motion:b.first] + b.lines[: b.motion] + b.lines[b.first:])
    invalid("junk_in_hierarchy", b.lines[:5] + ["SCALE 1 1 1"] + b.lines[5:], phrase="unexpected")
    invalid("end_site_without_site", [re.sub(r"End Site", "End", l) for l in b.lines])
    split = b.lines[b.first + 1].split()
    invalid("frame_split_in_two", b.lines[: b.first + 1] + [" ".join(split[:5]), " ".join(split[5:])] + b.lines[b.first + 2:])
    invalid("empty_frames_section", b.lines[: b.first], phrase="truncated")


def _chain(n: int, name="J", broken: bool = False) -> str:
    lines = ["HIERARCHY"]
    for j in range(n):
        lines += [("ROOT" if j == 0 else "JOINT") + f" {name}{j}", "{", "OFFSET 0 1.5 0",
                  "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" if j == 0 else
                  "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * (n - 1 if broken else n)
    values = " ".join(["0"] * (3 + 3 * n))
    lines += ["MOTION", "Frames: 2", "Frame Time: 0.0333333", values, values]
    return "\n".join(lines) + "\n"


def _wide(n: int, dup: bool = False) -> str:
    lines = ["HIERARCHY", "ROOT Root", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    for j in range(n):
        name = f"Child{0 if dup and j == n - 1 else j}"
        lines += [f"JOINT {name}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation",
                  "End Site", "{", "OFFSET 0 1 0", "}", "}"]
    values = " ".join(["0"] * (6 + 3 * n))
    lines += ["}", "MOTION", "Frames: 2", "Frame Time: 0.0333333", values, values]
    return "\n".join(lines) + "\n"


def _synthetic(rng: random.Random, add) -> None:
    """Files not derived from a real one: empty, junk, deep and wide hierarchies."""
    add("syn_empty", b"", False, phrase="empty")
    add("syn_whitespace_only", b" \n\t\r\n\n", False, phrase="empty")
    add("syn_only_hierarchy_word", b"HIERARCHY\n", False)
    add("syn_only_bom", b"\xef\xbb\xbf", False)
    add("syn_only_motion_word", b"MOTION\n", False)
    add("syn_only_nuls", b"\x00" * 1000, False)
    for j in range(6):
        add(f"syn_random_bytes{j}", bytes(rng.randrange(256) for _ in range(rng.randrange(1, 4000))), False)
    add("syn_random_text", "".join(rng.choice("{} \nROOTJOINT0123456789.-") for _ in range(5000)), False)
    for n in (999, 1000, 3000, 10_000):  # deep chains read (a spec cannot fit them: skipped on import)
        add(f"syn_chain_{n}", _chain(n), True, None, frames=2)
    add("syn_chain_10001", _chain(10_001), False, phrase="10,000 joints")
    add("syn_chain_1000_broken", _chain(1000, broken=True), False, phrase="end of hierarchy")
    add("syn_wide_4999", _wide(4999), True, None, frames=2)
    add("syn_wide_4999_duplicate", _wide(4999, dup=True), False, phrase="twice")
