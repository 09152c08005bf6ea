"""Student text made inert for every medium it is shown in: terminal, Markdown, plain text, CSV.

A submission controls much of what a report shows (its exception messages, its file name, its
notes), so every writer in this room passes such text through one of these functions and nowhere
else. Each keeps the text readable while making sure it cannot act: no terminal escape, no forged
line, no link or HTML in Markdown, no formula in a spreadsheet, and nothing that cannot be
encoded as UTF-8 (a lone surrogate from a hostile file name or message).
"""
from __future__ import annotations

import re

from autograder.core.results import encodable

TERMINAL_MESSAGE_CHARS = 90
"""A failure's message in the terminal summary is cut here (the feedback file has it whole)."""
MESSAGE_CHARS, NOTE_CHARS, NAME_CHARS = 2000, 600, 200
"""Student text shown at most this long: a failure's message, a note, a submission's name."""
QUOTE = "    | "
"""Each line of a failure's message in plain text starts with this, so no student text can pass
for a line of the grader's (a check mark, a score)."""
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069\u200b-\u200f\ufeff"
                      # invisible or blank characters (soft hyphen, joiners, fillers, selectors, tags)
                      r"\u00ad\u034f\u061c\u115f\u1160\u17b4\u17b5\u180b-\u180f\u2060-\u2065\u3164\ufe00-\ufe0f"
                      r"\uffa0\U0001d173-\U0001d17a\U000e0000-\U000e0fff]")
_MARKDOWN = re.compile(r"([\\`*_{}\[\]()#+!|<>~&$:=-])")
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r", "|", "%")


def cap(text: object, limit: int) -> str:
    """``text`` cut to ``limit`` characters, saying how much was left out."""
    text = encodable(str(text))
    return text if len(text) <= limit else text[:limit] + f"… ({len(text) - limit} more characters not shown)"


def plain(text: object) -> str:
    """``text`` without control characters (terminal escapes, carriage returns, bidirectional overrides,
    invisible characters) or unencodable ones: messages quote a student's exception text, which must not
    rewrite a terminal, forge a line, or stop a writer."""
    return _CONTROL.sub("?", encodable(str(text)))


def listed(names: list[str], shown: int = 20) -> str:
    """The first ``shown`` of ``names`` joined by commas, and how many more there are: a warning names whom it is
    about without growing with the class."""
    names = list(names)
    return ", ".join(names[:shown]) + (f" and {len(names) - shown} more" if len(names) > shown else "")


def one_line(text: object) -> str:
    """``text`` as :func:`plain`, on one line (newlines shown as ⏎)."""
    return plain(text).replace("\n", " ⏎ ").replace("\t", " ")


def markdown_text(text: object) -> str:
    """``text`` shown literally in Markdown: no link, image, heading, HTML, entity, emoji code, math or emphasis
    a student could forge (every Markdown punctuation is backslash-escaped; lines break with ``<br>``)."""
    return _MARKDOWN.sub(r"\\\1", plain(text)).replace("\n", "<br>")


def quoted_lines(text: object) -> list[str]:
    """``text`` as plain-text lines, each behind :data:`QUOTE`."""
    return [QUOTE + line for line in plain(text).split("\n")]


def csv_cell(text: object) -> str:
    """A CSV cell that a spreadsheet shows as text, never runs as a formula."""
    text = one_line(text)
    return "'" + text if text[:1] in _FORMULA_START else text


def points(value: float) -> str:
    """Points as a person writes them: ``2``, ``0.5``."""
    return f"{value:g}"
