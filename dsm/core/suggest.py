"""The nearest valid name to a misspelt one, for every "valid: ..." error of the kit (one wording)."""
from __future__ import annotations

import difflib

CUTOFF = 0.6            # difflib's ratio below which a name is no likely misspelling of another


def nearest(given, choices) -> list:
    """The valid choices closest to ``given`` by difflib's ratio (several only on a tie, in listed order)."""
    words = [str(c) for c in choices]
    if given is None or not words:
        return []
    near = difflib.get_close_matches(str(given), words, n=len(words), cutoff=CUTOFF)
    if not near:
        return []
    score = lambda w: difflib.SequenceMatcher(None, str(given), w).ratio()
    best = score(near[0])
    return [w for w in words if w in near and score(w) == best]


def did_you_mean(given, choices) -> str:
    """``did you mean 'x'? `` (with its trailing space) where a choice is near ``given``, else ``""``."""
    near = [w for w in nearest(given, choices) if w != str(given)]
    return f"did you mean {' or '.join(map(repr, near))}? " if near else ""


def valid_words(given, choices) -> str:
    """``did you mean 'x'? valid: a, b, c`` (the question only where a near choice exists)."""
    return f"{did_you_mean(given, choices)}valid: {', '.join(str(c) for c in choices)}"


def unknown(what: str, given, choices) -> str:
    """``unknown WHAT 'x' (did you mean 'y'? valid: ...)``: the one-line message for a name not in ``choices``."""
    return f"unknown {what} {given!r} ({valid_words(given, choices)})"
