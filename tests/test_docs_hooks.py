"""The docs' MkDocs hook turns the docstrings' Sphinx roles into references instead of literal text."""
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_sphinx_roles_become_references_with_their_short_names():
    hooks = _hooks()
    text = ("see :class:<code>~agents.search.policy.SearchPolicy</code>, :meth:<code>plan</code> and "
            ":func:<code>agents.search.mapf.validate</code>; `:class:` alone stays")
    out = hooks.on_page_content(text, None, None, None)
    assert ":class:<code>" not in out and ":meth:" not in out and ":func:" not in out
    assert '<autoref identifier="agents.search.policy.SearchPolicy" optional><code>SearchPolicy</code></autoref>' in out
    assert '<autoref identifier="plan" optional><code>plan()</code></autoref>' in out
    assert "<code>agents.search.mapf.validate()</code>" in out
    assert out.endswith("`:class:` alone stays")
