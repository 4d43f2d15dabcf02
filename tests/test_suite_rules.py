"""Rules for the test suite itself: a failing test says why it matters (issue #32).

pytest prints what a failed assertion compared; tests/conftest.py adds why the check matters
(tests/_why.py). These tests hold every test to having a reason to print, and run a failing test
through the real hook to see the section in pytest's output.
"""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

from _why import MIN_NAME_WORDS, name_sentence

TESTS = Path(__file__).resolve().parent


def _test_functions():
    for path in sorted(TESTS.rglob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name.startswith("test"):
                yield path.relative_to(TESTS).as_posix(), node


def test_every_test_has_a_docstring_or_a_sentence_for_a_name():
    """A failed test prints its docstring, else its name as a sentence: a name of fewer than
    five words ("test_bad_l_max") says too little, so such a test needs a docstring."""
    terse = [
        f"{path}::{node.name}"
        for path, node in _test_functions()
        if ast.get_docstring(node) is None and len(name_sentence(node.name).split()) < MIN_NAME_WORDS
    ]
    assert terse == [], (
        f"{len(terse)} tests have neither a docstring nor a name of ≥ {MIN_NAME_WORDS} words, so a"
        f" failure could not say why it matters: {terse}"
    )


def test_a_failing_test_prints_what_it_compared_and_why(tmp_path):
    """Run a failing test through tests/conftest.py's real report hook in a child pytest: the
    output must hold the compared values (assertion rewriting) and the docstring's reason."""
    (tmp_path / "conftest.py").write_text(
        textwrap.dedent(
            f"""
            import importlib.util
            _spec = importlib.util.spec_from_file_location("suite_conftest", {str(TESTS / "conftest.py")!r})
            _module = importlib.util.module_from_spec(_spec)
            _spec.loader.exec_module(_module)
            pytest_runtest_makereport = _module.pytest_runtest_makereport
            """
        ),
        encoding="utf-8",
    )
    (tmp_path / "test_sample.py").write_text(
        textwrap.dedent(
            '''
            """A sample module. Second sentence."""

            def test_documented():
                """Gold must reflect more red than blue, or metals look wrong."""
                red, blue = 0.2, 0.7
                assert red > blue

            def test_the_name_alone_must_say_why_it_fails():
                assert [1, 2] == [1, 3]
            '''
        ),
        encoding="utf-8",
    )
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "-p", "no:cacheprovider", str(tmp_path)],
        cwd=tmp_path,
        env={"PYTHONPATH": str(TESTS), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = run.stdout + run.stderr
    assert run.returncode == 1 and "2 failed" in out, out
    assert "why this test matters" in out, out
    assert "Gold must reflect more red than blue, or metals look wrong." in out, out
    assert "assert 0.2 > 0.7" in out, out  # what was compared
    assert "It checks that the name alone must say why it fails." in out, out
    assert "Module: A sample module." in out, out
