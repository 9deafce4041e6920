"""The API reference shows no Sphinx role as literal text: the docs build's griffe extension
(``docs/_griffe/sphinx_roles.py``) rewrites every role of the documented packages' docstrings into
a cross-reference to an object the reference renders, or into code text.

The objects the reference renders are computed here with mkdocstrings-python's own member filter
and the handler options of ``mkdocs.yml``, not with the extension's code.
"""
from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

griffe = pytest.importorskip("griffe")
yaml = pytest.importorskip("yaml")
mkdocstrings_python = pytest.importorskip("mkdocstrings_handlers.python")

ROOT = Path(__file__).resolve().parents[1]
EXTENSION = "docs/_griffe/sphinx_roles.py"
PACKAGES = ("agents", "baselines", "safe_mapf_envs")
#: any role, of any domain: what the built site must not show
ANY_ROLE = re.compile(r":(?:[a-z]+:)?[a-z]+:`")
#: an autorefs cross-reference as the extension writes it
LINK = re.compile(r"\[`[^`]+`\]\[([^\]]+)\]")


def _extension():
    spec = importlib.util.spec_from_file_location("docs_griffe_sphinx_roles", ROOT / EXTENSION)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class _ConfigLoader(yaml.SafeLoader):
    """Reads mkdocs.yml; tags such as ``!!python/name:`` become None."""


_ConfigLoader.add_multi_constructor("", lambda loader, suffix, node: None)


def _handler_options():
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=_ConfigLoader)
    plugin = next(p["mkdocstrings"] for p in config["plugins"] if isinstance(p, dict) and "mkdocstrings" in p)
    return config, mkdocstrings_python.PythonOptions.from_data(**plugin["handlers"]["python"]["options"])


def _defined(obj):
    yield obj
    for member in list(obj.members.values()):
        if not member.is_alias:
            yield from _defined(member)


def rendered_anchors(collection, identifiers, options):
    """The heading ids of the API pages, the way mkdocstrings-python's templates pick members."""
    anchors = set()

    def visit(obj):
        anchors.add(obj.path)
        if not (obj.is_module or obj.is_class):
            return
        for group in (obj.attributes, obj.type_aliases, obj.classes, obj.functions):
            kept = mkdocstrings_python.do_filter_objects(
                group, filters=options.filters, members_list=None, inherited_members=options.inherited_members,
                keep_no_docstrings=options.show_if_no_docstring)
            for member in kept:
                if member.is_imported and not member.is_public:
                    continue
                if obj.is_class and member.name == "__init__" and options.merge_init_into_class:
                    continue
                visit(member)

    for identifier in identifiers:
        visit(collection[identifier])
    return anchors


@pytest.fixture(scope="module")
def loaded():
    """The packages as written, and as the docs build loads them: with the extension, from one package."""
    ext = _extension()
    plain = griffe.ModulesCollection()
    plain_loader = griffe.GriffeLoader(search_paths=[str(ROOT)], modules_collection=plain)
    for name in PACKAGES:
        plain_loader.load(name)
    collection = griffe.ModulesCollection()
    loader = griffe.GriffeLoader(extensions=griffe.load_extensions(ext.SphinxRoles), search_paths=[str(ROOT)],
                                 modules_collection=collection)
    loader.load("baselines")
    _, options = _handler_options()
    identifiers = ext.api_identifiers()
    return ext, plain, collection, rendered_anchors(plain, identifiers, options)


def _docstrings(collection):
    for name in PACKAGES:
        for obj in _defined(collection[name]):
            if obj.docstring is not None:
                yield obj.path, obj.docstring.value


def test_the_docs_build_runs_the_extension_and_does_not_publish_it():
    config, options = _handler_options()
    assert EXTENSION in options.extensions
    assert "_griffe/" in config["exclude_docs"].split()
    assert options.docstring_style == "google"


def test_the_packages_hold_roles_and_the_pages_name_objects_of_them(loaded):
    ext, plain, _, anchors = loaded
    identifiers = ext.api_identifiers()
    assert {identifier.split(".")[0] for identifier in identifiers} == set(PACKAGES)
    assert sum(len(ANY_ROLE.findall(text)) for _, text in _docstrings(plain)) > 500
    assert "agents.search.execution.safety.SafetyLayer.for_env" in anchors
    assert "agents.search.execution.safety" in anchors and "agents.search" not in anchors


def test_no_docstring_keeps_a_role(loaded):
    _, _, collection, _ = loaded
    left = {path: ANY_ROLE.findall(text) for path, text in _docstrings(collection) if ANY_ROLE.search(text)}
    assert left == {}


def test_every_link_goes_to_a_rendered_object_and_most_roles_link(loaded):
    _, plain, collection, anchors = loaded
    targets = [target for _, text in _docstrings(collection) for target in LINK.findall(text)]
    assert sorted(set(targets) - anchors) == []
    # every role written with the full path of a rendered object links to it
    original = dict(_docstrings(plain))
    translated = dict(_docstrings(collection))
    checked = 0
    for path, text in original.items():
        for match in re.finditer(r":(?:class|meth|func|attr|mod|data|exc):`~?([\w.]+?)(?:\(\))?`", text):
            if match[1] in anchors:
                checked += 1
                assert f"][{match[1]}]" in translated[path], (path, match[0])
    assert checked > 150
    assert len(targets) > 450


@pytest.mark.parametrize("scope, text, expected", [
    # a full path; ``~`` shows the last component
    ("agents.search.policy", ":class:`~agents.search.execution.safety.SafetyLayer`",
     "[`SafetyLayer`][agents.search.execution.safety.SafetyLayer]"),
    ("agents.search.policy", ":class:`agents.search.execution.safety.SafetyLayer`",
     "[`agents.search.execution.safety.SafetyLayer`][agents.search.execution.safety.SafetyLayer]"),
    # a short name: the module's import
    ("agents.search.policy", ":class:`SafetyLayer`", "[`SafetyLayer`][agents.search.execution.safety.SafetyLayer]"),
    ("agents.search.policy", ":meth:`SafetyLayer.for_env`",
     "[`SafetyLayer.for_env()`][agents.search.execution.safety.SafetyLayer.for_env]"),
    # a method of the docstring's class
    ("agents.search.policy.SearchPolicy.predict", ":meth:`reset`",
     "[`reset()`][agents.search.policy.SearchPolicy.reset]"),
    # a name the package exports lazily
    ("agents.search.models", ":class:`~agents.SafeGoalTD3`", "[`SafeGoalTD3`][agents.algorithm.SafeGoalTD3]"),
    # an explicit title, over two lines
    ("safe_mapf_envs.multi_agent", ":meth:`NavigationScenario.sample_separated\n    "
     "<safe_mapf_envs.scenario.NavigationScenario.sample_separated>`",
     "[`NavigationScenario.sample_separated`][safe_mapf_envs.scenario.NavigationScenario.sample_separated]"),
    # other libraries, private and undocumented objects: code text
    ("agents.search.policy", ":class:`numpy.ndarray`", "`numpy.ndarray`"),
    ("agents.search.policy", ":class:`~gymnasium.Env`", "`Env`"),
    ("safe_mapf_envs.single_agent.SafeNavigationEnv", ":meth:`_setup`", "`_setup()`"),
    ("agents.search.policy", ":mod:`agents.search.mapf.cbs`", "`agents.search.mapf.cbs`"),
    # an inherited method of an undocumented base: not another class's method of that name
    ("safe_mapf_envs.single_agent.SafeNavigationEnv", ":meth:`observations_at`", "`observations_at()`"),
    # ``!``: no link
    ("agents.search.policy", ":class:`!SafetyLayer`", "`SafetyLayer`"),
    ("agents.search.policy", "``:class:`` plain", "``:class:`` plain"),
])
def test_roles_translate(loaded, scope, text, expected):
    ext, plain, _, _ = loaded
    resolver = ext.Resolver(plain, ext.documented_anchors(plain, ext.api_identifiers()))
    assert ext.translate(text, plain[scope], resolver) == expected
