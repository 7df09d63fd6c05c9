"""Phrase tables: how a dataset's labels are said in words, for the captions of exports that
carry text (HumanML3D's ``texts/``). A spec file's ``[text]`` table holds them; this module
reads it, each problem one :class:`~torchsplice.core.errors.SpecError` line naming the file
and key, and :mod:`torchsplice.formats.captions` composes captions from it.

The table::

    [text.locomotion]          # verb phrases, third person: "a person ___"
    key = "{content}"          # which labels of a clip choose its phrases (this is the default)
    walk = ["walks=walk/VERB forward/ADV", "walks=walk/VERB straight/ADV ahead/ADV"]
    [text.action]              # verb phrases too; spliced onto a locomotion: "... while ___ing"
    wave-right-hand = ["waves=wave/VERB the/DET right/ADJ hand/NOUN"]
    walk = []                  # says nothing (a styled walk: its style says it)
    [text.style]               # the subject (key "{style}" by default)
    normal = ["a/DET person/NOUN", "someone/PRON"]
    old = ["an/DET old/ADJ person/NOUN", "an/DET elderly/ADJ person/NOUN"]

A phrase is words separated by spaces, each ``word/POS`` or ``word=lemma/POS``: ``word`` is
what the caption says, ``lemma/POS`` its token (HumanML3D's tokens give nouns and verbs as
lemmas, so ``walks=walk/VERB``), POS one of spaCy's universal tags (:data:`POS_TAGS`); words
are letters only, as the format's tokens are (its loaders split each at ``/``). So
captions come with their tokens without a tagger. The ``key`` templates default to
``"{content}"`` (locomotion, action) and ``"{style}"``; a clip lacking a label its template
names has no key (so no phrase) for that part. Several phrases for one key are paraphrases.
"""

from __future__ import annotations

import functools
import importlib.resources
import re
from dataclasses import dataclass
from pathlib import Path

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from ..core.errors import SpecError
from .vocabulary import SHIPPED_PACKAGE

__all__ = [
    "Token",
    "PhraseTable",
    "POS_TAGS",
    "PARTS",
    "parse_phrase",
    "parse_phrase_table",
    "phrase_table",
    "spec_phrase_table",
]

POS_TAGS = (
    "ADJ",
    "ADP",
    "ADV",
    "AUX",
    "CCONJ",
    "DET",
    "INTJ",
    "NOUN",
    "NUM",
    "PART",
    "PRON",
    "PROPN",
    "PUNCT",
    "SCONJ",
    "SYM",
    "VERB",
    "X",
)
"""spaCy's universal part-of-speech tags, as HumanML3D's tokens carry them."""

PARTS = ("locomotion", "action", "style")
"""The parts of a caption a table says: what the legs do, what the arms do, who moves."""

_DEFAULT_KEYS = {"locomotion": "{content}", "action": "{content}", "style": "{style}"}
_WORD = re.compile(r"^([A-Za-z]+)(?:=([A-Za-z]+))?/([A-Z]+)$")
_FIELD = re.compile(r"\{([^{}]+)\}")


@dataclass(frozen=True)
class Token:
    """One word of a caption: ``word`` as written, its token ``lemma/pos``."""

    word: str
    lemma: str
    pos: str


Phrase = tuple  # tuple[Token, ...]


def parse_phrase(text: str, where: str = "phrase") -> Phrase:
    """The :class:`Token` s of a phrase written ``word/POS`` or ``word=lemma/POS``, space separated;
    one-line :class:`SpecError` naming ``where`` otherwise."""
    if not isinstance(text, str):
        raise SpecError(f"{where}: expected a phrase (text), got {type(text).__name__}")
    tokens = []
    for item in text.split():
        m = _WORD.fullmatch(item)
        if m is None:
            raise SpecError(f"{where}: {item!r} is not word/POS or word=lemma/POS, words of letters only (in {text!r})")
        word, lemma, pos = m.group(1), m.group(2) or m.group(1), m.group(3)
        if pos not in POS_TAGS:
            raise SpecError(f"{where}: {item!r}: unknown part of speech {pos!r} (one of {', '.join(POS_TAGS)})")
        tokens.append(Token(word, lemma.lower(), pos))
    if not tokens:
        raise SpecError(f"{where}: empty phrase")
    return tuple(tokens)


@dataclass(frozen=True)
class PhraseTable:
    """A spec's ``[text]`` table (see the module docstring).

    Attributes:
        name: the spec it belongs to.
        keys: per part (:data:`PARTS`), the key template (``"{content}"``).
        phrases: per part, per key, its phrases (``()``: the key says nothing).
    """

    name: str
    keys: dict
    phrases: dict

    def key(self, part: str, labels: dict) -> str | None:
        """The key of ``part`` for a clip with ``labels``; ``None`` when a label it names is missing."""
        names = _FIELD.findall(self.keys[part])
        if any(not labels.get(n) for n in names):
            return None
        return _FIELD.sub(lambda m: str(labels[m.group(1)]), self.keys[part])

    def lookup(self, part: str, labels: dict) -> tuple | None:
        """The phrases of ``part`` for ``labels``: a tuple of phrases (maybe empty: the key says
        nothing), or ``None`` when the table has no entry for it."""
        key = self.key(part, labels)
        return None if key is None else self.phrases[part].get(key)


def parse_phrase_table(table, where: str, name: str) -> PhraseTable:
    """A :class:`PhraseTable` from a spec's ``[text]`` table (a dict); one-line errors naming ``where``."""
    if not isinstance(table, dict):
        raise SpecError(f"{where}: [text] must be a table, got {type(table).__name__}")
    extra = sorted(set(table) - set(PARTS))
    if extra:
        raise SpecError(f"{where}: [text] {extra[0]}: unknown key (allowed: {', '.join(PARTS)})")
    keys, phrases = dict(_DEFAULT_KEYS), {}
    for part in PARTS:
        value = table.get(part, {})
        if isinstance(value, str):
            raise SpecError(
                f"{where}: [text] {part}: give the phrases as a table [text.{part}] (its key template "
                f"as key = {value!r} in it)"
            )
        if not isinstance(value, dict):
            raise SpecError(f"{where}: [text.{part}] must be a table, got {type(value).__name__}")
        entries = {}
        for key, items in value.items():
            if key == "key" and isinstance(items, str):
                if not _FIELD.search(items):
                    raise SpecError(f'{where}: [text.{part}] key: {items!r} names no label (such as "{{content}}")')
                keys[part] = items
                continue
            if isinstance(items, str):
                items = [items]
            if not isinstance(items, list):
                raise SpecError(f"{where}: [text.{part}] {key}: expected a list of phrases, got {type(items).__name__}")
            entries[key] = tuple(parse_phrase(p, f"{where}: [text.{part}] {key}") for p in items)
        phrases[part] = entries
    return PhraseTable(name, keys, phrases)


@functools.lru_cache(maxsize=64)
def phrase_table(path) -> PhraseTable | None:
    """The phrase table of the spec file at ``path`` (``None`` if it has no ``[text]``)."""
    path = Path(str(path))
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SpecError(f"{path}: cannot read its [text] table ({' '.join(str(exc).split())})") from None
    if "text" not in data:
        return None
    return parse_phrase_table(data["text"], str(path), path.stem)


def spec_phrase_table(spec) -> PhraseTable | None:
    """The phrase table of a :class:`~torchsplice.specs.DatasetSpec`: its file's (a spec stored in
    a database keeps its file's path), else the shipped spec of its name; ``None`` if none."""
    path = getattr(spec, "path", None)
    if path is not None and Path(path).is_file():
        return phrase_table(Path(path))
    shipped = importlib.resources.files(SHIPPED_PACKAGE) / f"{spec.name}.toml"
    if shipped.is_file():
        return phrase_table(Path(str(shipped)))
    return None
