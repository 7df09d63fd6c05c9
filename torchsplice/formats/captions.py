"""Captions of clips, composed from their labels: what text-to-motion training reads beside each
motion (HumanML3D's ``texts/ID.txt``).

A caption is a sentence and its tokens (:class:`Caption`). HumanML3D writes one a line::

    a person walks forward while waving the right hand#a/DET person/NOUN walk/VERB forward/ADV while/SCONJ wave/VERB the/DET right/ADJ hand/NOUN#0.0#0.0

(the sentence, its words as ``lemma/POS``, and the start and end in seconds of the part it
describes; ``0.0#0.0``: the whole clip). Tokens are alphabetic words only; nouns and verbs
are given as lemmas (as spaCy's lemmatizer gives them; ``left`` stays ``left``).

Where the words come from, for a clip (:func:`clip_captions`):

- a spliced clip says ``SUBJECT LOCOMOTION while ACTION-ing``: the subject from the action's
  style (else the locomotion's, else "a person" / "someone" / "the person"), the locomotion's
  verb phrase, and the action's verb phrase turned into a gerund (:func:`gerund`; nothing when
  the action's phrase is empty, e.g. a styled walk whose style says it all);
- a source clip says ``SUBJECT LOCOMOTION`` (a locomotion, or both) or ``SUBJECT ACTION`` (an
  action);
- a clip the user's captions name itself (a result, or a source clip) gets those, as they are;
- each part is, first found: the user's captions of that source clip (:func:`read_captions`,
  a caption's subject and verb phrase split at its first verb; a caption that is itself a
  splice, "walks forward while waving", gives the locomotion before ``while`` and the action
  after it), the clip's own captions
  (label ``captions``, as a HumanML3D import keeps them), or the phrase tables of the specs
  (:mod:`torchsplice.specs.text`: the clip's own spec's, then every shipped spec's);
- paraphrases: every combination of the parts' phrases, up to ``count``, in an order fixed by
  the clip's name.

:func:`mirror_caption` swaps left and right (and clockwise and counterclockwise) in a
caption, for mirrored copies. This module imports no torch.
"""

from __future__ import annotations

import itertools
import json
import math
import random
import re
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from ..core.errors import TorchspliceError
from ..specs.text import POS_TAGS, PhraseTable, Token, parse_phrase
from .plain_files import read_capped_text

__all__ = ["Caption", "Clause", "clip_captions", "compose", "gerund", "mirror_caption", "parse_caption_line",
           "read_captions", "CAPTION_LABEL", "DEFAULT_SUBJECTS", "MOVES"]

CAPTION_LABEL = "captions"
"""The label holding a clip's own captions (HumanML3D lines, one a line), as an import keeps them."""

DEFAULT_SUBJECTS = tuple(parse_phrase(p) for p in ("a/DET person/NOUN", "someone/PRON", "the/DET person/NOUN"))
"""Who moves, where no style says it."""

MOVES = parse_phrase("moves=move/VERB")
"""What a locomotion does when nothing says it (counted as undescribed)."""

_MIRROR = {"left": "right", "right": "left", "clockwise": "counterclockwise", "counterclockwise": "clockwise",
           "anticlockwise": "clockwise", "counter-clockwise": "clockwise", "anti-clockwise": "clockwise",
           "leftward": "rightward", "rightward": "leftward", "leftwards": "rightwards", "rightwards": "leftwards",
           "lefthanded": "righthanded", "righthanded": "lefthanded"}
LOCOMOTION_VERBS = frozenset((
    "walk", "run", "jog", "step", "sidestep", "stroll", "march", "jump", "hop", "skip", "turn", "move", "go", "sprint",
    "dash", "limp", "stride", "shuffle", "pace", "wander", "circle", "strut", "tiptoe", "stumble", "climb", "descend",
    "ascend", "crawl", "travel", "proceed", "head", "approach", "advance", "retreat", "backpedal"))
"""Verbs that say what the legs do: of a caption that is itself "X while Y", the half led by one
is its locomotion, the other its action."""
_VOWELS = set("aeiou")


@dataclass(frozen=True)
class Caption:
    """A sentence, its tokens ``((lemma, pos), ...)``, and the part of the clip it describes:
    ``start`` and ``end`` in seconds (``0.0, 0.0``: the whole clip, as HumanML3D writes it)."""

    text: str
    tokens: tuple
    start: float = 0.0
    end: float = 0.0

    def line(self) -> str:
        """The caption as one line of a HumanML3D text file."""
        return f"{self.text}#{' '.join(f'{w}/{p}' for w, p in self.tokens)}#{self.start}#{self.end}"

    def within(self, start: float, end: float) -> "Caption | None":
        """The caption of the window ``start..end`` (seconds) of its clip: a whole-clip caption as
        it is; a part's, moved into the window's time (``None`` when it lies outside it)."""
        if self.start == 0.0 and self.end == 0.0:
            return self
        a, b = max(self.start, start), min(self.end, end)
        if b <= a:
            return None
        return Caption(self.text, self.tokens, round(a - start, 4), round(b - start, 4))


@dataclass(frozen=True)
class Clause:
    """Words with their tokens, and where its first verb is (index into ``words``, ``None`` if
    none is known). ``words`` and ``tokens`` correspond one to one when ``aligned``."""

    words: tuple
    tokens: tuple
    verb: int | None = None
    aligned: bool = True

    @classmethod
    def of(cls, phrase: Sequence[Token]) -> "Clause":
        verb = next((i for i, t in enumerate(phrase) if t.pos in ("VERB", "AUX")), None)
        return cls(tuple(t.word for t in phrase), tuple((t.lemma, t.pos) for t in phrase), verb)

    def split(self) -> tuple["Clause | None", "Clause"]:
        """``(subject, predicate)`` at the first verb (no subject: ``None``)."""
        if self.verb is None or self.verb == 0:
            return None, self
        t = self.verb if self.aligned else _token_verb(self.tokens)
        return (Clause(self.words[:self.verb], self.tokens[:t], None, self.aligned),
                Clause(self.words[self.verb:], self.tokens[t:], 0, self.aligned))


def _token_verb(tokens) -> int:
    return next((i for i, (_, p) in enumerate(tokens) if p in ("VERB", "AUX")), 0)


def gerund(lemma: str) -> str:
    """The ``-ing`` form of a verb's lemma: ``wave`` -> ``waving``, ``run`` -> ``running``,
    ``carry`` -> ``carrying``, ``lie`` -> ``lying``, ``see`` -> ``seeing``."""
    w = lemma.lower()
    if w.endswith("ie"):
        return w[:-2] + "ying"
    if w.endswith("e") and not w.endswith(("ee", "ye", "oe")) and len(w) > 2:
        return w[:-1] + "ing"
    if w.endswith(("step", "stop", "drop", "skip", "trip", "ship", "slip", "flip", "wrap", "grab")):
        return w + w[-1] + "ing"  # compounds of a short stressed syllable: sidestep
    groups = re.findall(r"[aeiou]+", w)
    if (len(groups) == 1 and len(w) >= 3 and w[-1] not in _VOWELS | set("wxy") and w[-2] in _VOWELS
            and w[-3] not in _VOWELS and len(groups[0]) == 1):
        return w + w[-1] + "ing"  # one short vowel before one consonant: run, step, jog, clap
    return w + "ing"


def _as_gerund(clause: Clause) -> Clause:
    if clause.verb is None:
        return clause
    words, tokens = list(clause.words), list(clause.tokens)
    t = clause.verb if clause.aligned else _token_verb(clause.tokens)
    if (tokens[t][1] == "AUX" and tokens[t][0] in ("be", "is", "are") and t + 1 < len(tokens)
            and tokens[t + 1][1] == "VERB" and clause.verb + 1 < len(words)):
        # "is waving": the progressive's verb is the gerund already; the auxiliary goes
        del words[clause.verb], tokens[t]
        return Clause(tuple(words), tuple(tokens), clause.verb, clause.aligned)
    words[clause.verb] = gerund(tokens[t][0])
    return Clause(tuple(words), tuple(tokens), clause.verb, clause.aligned)


def compose(subject: Clause, locomotion: Clause, action: Clause | None = None) -> Caption:
    """``SUBJECT LOCOMOTION [while ACTION-ing]`` as a :class:`Caption`."""
    words = list(subject.words) + list(locomotion.words)
    tokens = list(subject.tokens) + list(locomotion.tokens)
    if action is not None and action.words:
        action = _as_gerund(action)
        words += ["while"] + list(action.words)
        tokens += [("while", "SCONJ")] + list(action.tokens)
    return Caption(" ".join(words), tuple(tokens))


def mirror_caption(caption: Caption) -> Caption:
    """The caption of a mirrored clip: left and right (clockwise and counterclockwise) swapped."""
    def swap(word: str) -> str:
        other = _MIRROR.get(word.lower())
        if other is None:
            return word
        return other.capitalize() if word[:1].isupper() else other

    def swap_compound(word: str) -> str:
        whole = swap(word)
        if whole != word or "-" not in word:
            return whole
        return "-".join(swap(part) if part.lower() in ("left", "right") else part for part in word.split("-"))

    text = re.sub(r"[A-Za-z]+(?:-[A-Za-z]+)*", lambda m: swap_compound(m.group(0)), caption.text)
    return Caption(text, tuple((swap(w), p) for w, p in caption.tokens), caption.start, caption.end)


def parse_caption_line(line: str, where: str) -> Caption:
    """A HumanML3D text line (``caption#tokens#start#end``; ``#start#end`` optional) as a
    :class:`Caption`, or a phrase written ``word/POS`` / ``word=lemma/POS``; one-line error
    naming ``where`` otherwise."""
    text = line.strip()
    if "#" in text:
        parts = text.split("#")
        if len(parts) not in (2, 4) or not parts[0].strip():
            raise TorchspliceError(f"{where}: {_short(text)!r} is not 'caption#tokens#start#end'")
        tokens = []
        for item in parts[1].split():
            word, sep, pos = item.partition("/")
            if not sep or not word.isalpha() or pos not in POS_TAGS:
                raise TorchspliceError(f"{where}: token {item!r} is not word/POS (a word of letters, a universal tag; "
                                       f"in {_short(text)!r})")
            tokens.append((word, pos))
        if not tokens:
            raise TorchspliceError(f"{where}: {_short(text)!r} has no tokens")
        times = [0.0, 0.0]
        if len(parts) == 4:
            for k, value in enumerate(parts[2:]):
                try:
                    times[k] = float(value)
                except ValueError:
                    raise TorchspliceError(f"{where}: start or end {value!r} is not a number (in {_short(text)!r})") from None
                if not math.isfinite(times[k]) or times[k] < 0:
                    raise TorchspliceError(f"{where}: start or end {value!r} is not a time in seconds (in {_short(text)!r})")
            if times[1] < times[0] and times[1] != 0.0:
                raise TorchspliceError(f"{where}: ends ({times[1]:g} s) before it starts ({times[0]:g} s) (in {_short(text)!r})")
        return Caption(" ".join(parts[0].split()), tuple(tokens), times[0], times[1])
    try:
        phrase = parse_phrase(text, where)
    except Exception as exc:  # a SpecError: say it as a caption problem
        raise TorchspliceError(f"{' '.join(str(exc).split())} (a caption is 'caption#tokens#start#end' or "
                               "word/POS words)") from None
    return Caption(" ".join(t.word for t in phrase), tuple((t.lemma, t.pos) for t in phrase))


def _short(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _caption_clause(caption: Caption) -> Clause:
    """A full caption as a clause: its verb found by its tokens (words and tokens may differ in
    number: punctuation, contractions)."""
    words = tuple(re.sub(r"[.!?;,]+$", "", w) for w in caption.text.split())
    words = tuple(w for w in words if w)
    t = next((i for i, (_, p) in enumerate(caption.tokens) if p in ("VERB", "AUX")), None)
    verb = None
    if t is not None:
        lemma = caption.tokens[t][0].lower()
        for i in range(len(words)):  # the first word that reads as that verb
            w = re.sub(r"[^a-z]", "", words[i].lower())
            if w and (w.startswith(lemma[:max(2, len(lemma) - 1)]) or i == t):
                verb = i
                break
    return Clause(words, caption.tokens, verb, aligned=False)


def _half(predicate: Clause, part: str) -> Clause:
    """The part of a caption's predicate that says ``part``: a caption that is itself a splice
    ("walks forward while waving") gives its locomotion before ``while`` and its action after."""
    wi = next((i for i, w in enumerate(predicate.words) if w.lower() == "while"), None)
    ti = next((i for i, t in enumerate(predicate.tokens) if t == ("while", "SCONJ")), None)
    if wi is None or ti is None or wi == 0 or wi == len(predicate.words) - 1:
        return predicate
    first = Clause(predicate.words[:wi], predicate.tokens[:ti], predicate.verb, predicate.aligned)
    second = Clause(predicate.words[wi + 1:], predicate.tokens[ti + 1:], 0, predicate.aligned)
    # the half led by a verb of the legs is the locomotion ("walks while waving", "waves while walking")
    legs_first = _leads_with_legs(first) or not _leads_with_legs(second)
    return (first if legs_first else second) if part == "locomotion" else (second if legs_first else first)


def _leads_with_legs(clause: Clause) -> bool:
    verb = next((lemma for lemma, pos in clause.tokens if pos == "VERB"), None)
    return verb in LOCOMOTION_VERBS


def read_captions(path) -> dict[str, list[Caption]]:
    """A user's captions per source clip: a JSON object ``{"clip name": ["caption", ...]}``, each
    caption a HumanML3D line (``caption#tokens#start#end``) or ``word/POS`` words. One-line
    errors naming the file."""
    path = Path(path)
    if not (path.exists() or path.is_symlink()):
        raise TorchspliceError(f"{path}: no such captions file")
    try:
        data = json.loads(read_capped_text(path, limit=64 << 20))  # not a FIFO, not /dev/zero
    except json.JSONDecodeError as exc:
        raise TorchspliceError(f"{path}: not a JSON captions file ({' '.join(str(exc).split())})") from None
    if not isinstance(data, dict):
        raise TorchspliceError(f"{path}: expected an object mapping clip names to lists of captions")
    out = {}
    for name, items in data.items():
        if isinstance(items, str):
            items = [items]
        if not isinstance(items, list) or not items or not all(isinstance(i, str) for i in items):
            raise TorchspliceError(f"{path}: {name!r}: expected a list of captions (text)")
        out[name] = [parse_caption_line(i, f"{path}: {name!r}") for i in items]
        for caption in out[name]:
            for lemma, pos in caption.tokens:
                if pos == "VERB" and _inflected(lemma):
                    raise TorchspliceError(
                        f"{path}: {name!r}: verb {lemma!r} reads as inflected; the composer inflects verbs itself "
                        "(walks while waving), so give a verb as its base form: the word as written, then its base "
                        "form (waves=wave/VERB), or the base form alone (wave/VERB)")
    return out


_BASE_ING = {"bring", "sing", "swing", "ring", "sting", "fling", "cling", "spring", "string", "wring", "sling", "wing"}


def _inflected(lemma: str) -> bool:
    """Whether a verb's given base form reads as an inflected one (``waves``, ``walked``,
    ``walking``), which the composer would inflect again (``wavesing``)."""
    w = lemma.lower()
    if len(w) >= 5 and w.endswith("ing") and w not in _BASE_ING:
        return True
    if len(w) >= 5 and w.endswith("ed") and w[-3] not in "ea":
        return True
    return len(w) >= 4 and w.endswith("s") and w[-2] not in "suia"


def own_captions(labels: dict, where: str) -> list[Caption]:
    """The captions a clip's ``labels`` hold (:data:`CAPTION_LABEL`, one line each)."""
    text = labels.get(CAPTION_LABEL, "")
    return [parse_caption_line(line, where) for line in text.splitlines() if line.strip()]


def _lookup(tables: Sequence[PhraseTable], part: str, labels: dict):
    for table in tables:
        found = table.lookup(part, labels)
        if found is not None:
            return [Clause.of(p) for p in found]
    return None


def _source_parts(name: str, labels: dict, user: dict, tables, part: str, where: str):
    """``(subjects, predicates)`` of a source clip's part: from the user's captions, its own,
    or the phrase tables (``None`` where nothing says it)."""
    given = _given(name, labels, user, where)
    if given:
        split = [_caption_clause(c).split() for c in given]
        subjects = [s for s, _ in split if s is not None]
        return subjects or None, list(dict.fromkeys(_half(p, part) for _, p in split))
    style = _lookup(tables, "style", labels)
    return style or None, _lookup(tables, part, labels)


def _given(name: str, labels: dict, user: dict, where: str) -> list[Caption]:
    """The user's captions of a clip (or of the take it was cut from), else its own."""
    return user.get(name) or user.get(labels.get("split_from", "")) or own_captions(labels, where)


def clip_captions(name: str, role: str, labels: dict, tables: Sequence[PhraseTable], user: dict | None = None,
                  count: int = 3, locomotion: str = "", action: str = "") -> tuple[list[Caption], bool]:
    """The captions of one clip (see the module docstring) and whether its motion was described
    (``False``: its locomotion could only be said to "move", or its action was not said).

    Args:
        name, role, labels: the clip's name, role and labels (a spliced clip's sources' labels
            prefixed ``locomotion.`` and ``action.``).
        tables: phrase tables to look labels up in, first found wins.
        user: the user's captions by source clip name (:func:`read_captions`).
        count: at most this many paraphrases (a clip's own or the user's captions of it are kept,
            every one).
        locomotion, action: a spliced clip's sources' names.
    """
    user = user or {}
    where = f"clip {name!r}"
    if role == "spliced" and user.get(name):  # the user's captions of this very result
        return list(user[name]), True
    if role == "spliced":
        loco_labels = {k[11:]: v for k, v in labels.items() if k.startswith("locomotion.")}
        act_labels = {k[7:]: v for k, v in labels.items() if k.startswith("action.")}
        l_subjects, l_preds = _source_parts(locomotion, loco_labels, user, tables, "locomotion", where)
        a_subjects, a_preds = _source_parts(action, act_labels, user, tables, "action", where)
        subjects = a_subjects or l_subjects or [Clause.of(p) for p in DEFAULT_SUBJECTS]
        actions = a_preds if a_preds is not None else [None]
        # described when the legs are said and the action is (an empty phrase list: said to add nothing)
        described = bool(l_preds) and a_preds is not None
        locos = l_preds if l_preds else [Clause.of(MOVES)]
    else:
        given = _given(name, labels, user, where)
        if given:  # the clip's own (or the user's) captions, every one, with their times
            return list(given), True
        subjects = _lookup(tables, "style", labels) or [Clause.of(p) for p in DEFAULT_SUBJECTS]
        part = "action" if role == "action" else "locomotion"
        preds = _lookup(tables, part, labels)
        described = bool(preds)
        locos = preds if preds else [Clause.of(MOVES)]
        actions = [None]
    combos = list(itertools.product(range(len(subjects)), range(len(locos)), range(len(actions or [None]))))
    random.Random(zlib.crc32(name.encode("utf-8", "surrogatepass"))).shuffle(combos)
    out, seen = [], set()
    for s, l, a in combos:
        caption = compose(subjects[s], locos[l], (actions or [None])[a])
        if caption.text not in seen:
            seen.add(caption.text)
            out.append(caption)
        if len(out) == count:
            break
    return out, described
