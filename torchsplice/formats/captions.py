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
import random
import re
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from ..core.errors import TorchspliceError
from ..specs.text import POS_TAGS, PhraseTable, Token, parse_phrase

__all__ = ["Caption", "Clause", "clip_captions", "compose", "gerund", "mirror_caption", "parse_caption_line",
           "read_captions", "CAPTION_LABEL", "DEFAULT_SUBJECTS", "MOVES"]

CAPTION_LABEL = "captions"
"""The label holding a clip's own captions (HumanML3D lines, one a line), as an import keeps them."""

DEFAULT_SUBJECTS = tuple(parse_phrase(p) for p in ("a/DET person/NOUN", "someone/PRON", "the/DET person/NOUN"))
"""Who moves, where no style says it."""

MOVES = parse_phrase("moves=move/VERB")
"""What a locomotion does when nothing says it (counted as undescribed)."""

_MIRROR = {"left": "right", "right": "left", "clockwise": "counterclockwise", "counterclockwise": "clockwise",
           "anticlockwise": "clockwise", "leftward": "rightward", "rightward": "leftward", "leftwards": "rightwards",
           "rightwards": "leftwards"}
_VOWELS = set("aeiou")


@dataclass(frozen=True)
class Caption:
    """A sentence and its tokens ``((lemma, pos), ...)``."""

    text: str
    tokens: tuple

    def line(self, start: float = 0.0, end: float = 0.0) -> str:
        """The caption as one line of a HumanML3D text file."""
        return f"{self.text}#{' '.join(f'{w}/{p}' for w, p in self.tokens)}#{start}#{end}"


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
    words = list(clause.words)
    t = clause.verb if clause.aligned else _token_verb(clause.tokens)
    words[clause.verb] = gerund(clause.tokens[t][0])
    return Clause(tuple(words), clause.tokens, clause.verb, clause.aligned)


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

    text = re.sub(r"[A-Za-z]+", lambda m: swap(m.group(0)), caption.text)
    return Caption(text, tuple((swap(w), p) for w, p in caption.tokens))


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
            word, sep, pos = item.rpartition("/")
            if not sep or not word or pos not in POS_TAGS:
                raise TorchspliceError(f"{where}: token {item!r} is not word/POS with a universal tag (in {_short(text)!r})")
            tokens.append((word, pos))
        if not tokens:
            raise TorchspliceError(f"{where}: {_short(text)!r} has no tokens")
        if len(parts) == 4:
            for value in parts[2:]:
                try:
                    float(value)
                except ValueError:
                    raise TorchspliceError(f"{where}: start or end {value!r} is not a number (in {_short(text)!r})") from None
        return Caption(" ".join(parts[0].split()), tuple(tokens))
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
    if part == "locomotion":
        return Clause(predicate.words[:wi], predicate.tokens[:ti], predicate.verb, predicate.aligned)
    return Clause(predicate.words[wi + 1:], predicate.tokens[ti + 1:], 0, predicate.aligned)


def read_captions(path) -> dict[str, list[Caption]]:
    """A user's captions per source clip: a JSON object ``{"clip name": ["caption", ...]}``, each
    caption a HumanML3D line (``caption#tokens#start#end``) or ``word/POS`` words. One-line
    errors naming the file."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise TorchspliceError(f"{path}: no such captions file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
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
    return out


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
    given = user.get(name) or own_captions(labels, where)
    if given:
        split = [_caption_clause(c).split() for c in given]
        subjects = [s for s, _ in split if s is not None]
        return subjects or None, list(dict.fromkeys(_half(p, part) for _, p in split))
    style = _lookup(tables, "style", labels)
    return style or None, _lookup(tables, part, labels)


def clip_captions(name: str, role: str, labels: dict, tables: Sequence[PhraseTable], user: dict | None = None,
                  count: int = 3, locomotion: str = "", action: str = "") -> tuple[list[Caption], bool]:
    """The captions of one clip (see the module docstring) and whether its motion was described
    (``False``: only "moves" could be said of it).

    Args:
        name, role, labels: the clip's name, role and labels (a spliced clip's sources' labels
            prefixed ``locomotion.`` and ``action.``).
        tables: phrase tables to look labels up in, first found wins.
        user: the user's captions by source clip name (:func:`read_captions`).
        count: at most this many paraphrases.
        locomotion, action: a spliced clip's sources' names.
    """
    user = user or {}
    where = f"clip {name!r}"
    if role == "spliced":
        loco_labels = {k[11:]: v for k, v in labels.items() if k.startswith("locomotion.")}
        act_labels = {k[7:]: v for k, v in labels.items() if k.startswith("action.")}
        l_subjects, l_preds = _source_parts(locomotion, loco_labels, user, tables, "locomotion", where)
        a_subjects, a_preds = _source_parts(action, act_labels, user, tables, "action", where)
        subjects = a_subjects or l_subjects or [Clause.of(p) for p in DEFAULT_SUBJECTS]
        actions = a_preds if a_preds is not None else [None]
        described = l_preds is not None
        locos = l_preds if l_preds is not None else [Clause.of(MOVES)]
    else:
        given = user.get(name) or own_captions(labels, where)
        if given:
            return given[:count] if count else given, True
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
