"""What a failing test prints besides the values pytest shows: why the check matters.

pytest's assertion rewriting prints what was compared (both sides, their parts); the reason is
the test's docstring, else the sentence its name spells (``test_gold_is_yellow`` → "gold is
yellow"), with the module's first docstring line for context. :func:`reason` builds that text;
tests/conftest.py adds it to a failed test's report as a section of its own, and
tests/test_suite_rules.py checks that every test has a docstring or a name of at least
:data:`MIN_NAME_WORDS` words, so the section always says something.
"""

from __future__ import annotations

import inspect

#: Words (after ``test``) a test's name needs to stand for its docstring.
MIN_NAME_WORDS = 5


def name_sentence(name: str) -> str:
    """``test_a_finished_bake_asks_for_a_redraw[param]`` → "a finished bake asks for a redraw"."""
    base = name.split("[", 1)[0]
    return base.removeprefix("test_").replace("_", " ").strip()


def first_paragraph(text: str | None) -> str:
    """The first paragraph of a docstring, unwrapped ("" for none)."""
    if not text:
        return ""
    return " ".join(inspect.cleandoc(text).split("\n\n", 1)[0].split())


def reason(item) -> str:
    """The text shown under a failed test: why it matters (docstring or name) and its module."""
    function = getattr(item, "function", None)
    why = first_paragraph(getattr(function, "__doc__", None)) or f"It checks that {name_sentence(item.name)}."
    module = first_paragraph(getattr(getattr(item, "module", None), "__doc__", None))
    lines = [why]
    if module:
        lines.append(f"Module: {module.split('. ', 1)[0].rstrip('.')}.")
    lines.append("The values compared are printed above (pytest's assertion rewriting).")
    return "\n".join(lines)
