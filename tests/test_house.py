"""The shape of the packages: imports that flow one way, no aliases.

Read from the source with :mod:`ast` (nothing is imported), so the rules hold for every module,
also those a test never imports: no import circle among the modules of ``agents/``, ``baselines/``
and ``safe_mapf_envs/``, counting imports inside functions
(imports under ``if TYPE_CHECKING:`` are for the type checker only and do not count); and no
module that only re-exports names of another module.
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, List, Set

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("agents", "baselines", "safe_mapf_envs")


def module_files() -> Dict[str, Path]:
    """Dotted module name -> file, for every module of the packages (a package is its ``__init__``)."""
    out = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = module_files()


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST) -> List[ast.stmt]:
    """Every import statement of a module, at any depth, except under ``if TYPE_CHECKING:``."""
    found: List[ast.stmt] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def imported_modules(name: str) -> Set[str]:
    """The package modules that module ``name`` imports (``from pkg import sub`` counts as ``pkg.sub``)."""
    path = MODULES[name]
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: Set[str] = set()
    for node in _imports(tree):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
            continue
        assert isinstance(node, ast.ImportFrom)
        if node.level:
            base = package.split(".")
            base = base[: len(base) - (node.level - 1)]
            source = ".".join(base + ([node.module] if node.module else []))
        else:
            source = node.module or ""
        for alias in node.names:
            sub = f"{source}.{alias.name}"
            targets.add(sub if sub in MODULES else source)
    return {t for t in targets if t in MODULES and t != name}


def import_cycles() -> List[List[str]]:
    """The strongly connected components of more than one module in the import graph (Tarjan)."""
    graph = {name: sorted(imported_modules(name)) for name in MODULES}
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    components: List[List[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in graph:
        if v not in index:
            connect(v)
    return components


def test_the_packages_are_found():
    assert {"agents.policies", "baselines.evaluation", "safe_mapf_envs.multi_agent"} <= set(MODULES)


def test_no_import_circle_among_the_package_modules():
    assert import_cycles() == []


def test_the_cycle_finder_sees_function_level_imports_and_ignores_type_checking(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from . import b\n")
    (pkg / "b.py").write_text("from pkg.a import f\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .b import x\n")
    (pkg / "d.py").write_text("from .c import y\n")
    modules = {"pkg": pkg / "__init__.py", **{f"pkg.{m}": pkg / f"{m}.py" for m in "abcd"}}
    monkeypatch.setitem(globals(), "MODULES", modules)
    assert import_cycles() == [["pkg.a", "pkg.b"]]
    assert imported_modules("pkg.c") == set()
    assert imported_modules("pkg.d") == {"pkg.c"}


def only_reexports(path: Path) -> bool:
    """Whether a module (not a package ``__init__``) holds nothing but a docstring, imports and
    ``__all__``: a second name for another module."""
    body = ast.parse(path.read_text()).body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        body = body[1:]
    rest = [s for s in body if not isinstance(s, (ast.Import, ast.ImportFrom))]
    imports_something = len(rest) < len(body)
    aliases = all(
        isinstance(s, (ast.Assign, ast.AnnAssign)) and isinstance(getattr(s, "value", None), (ast.Name, ast.List,
                                                                                              ast.Tuple, ast.Attribute))
        for s in rest)
    return imports_something and aliases


def test_no_module_only_reexports_another():
    aliases = [str(p.relative_to(ROOT)) for name, p in MODULES.items()
               if p.name != "__init__.py" and only_reexports(p)]
    assert aliases == []


def test_the_reexport_finder_recognises_an_alias_module(tmp_path):
    alias = tmp_path / "old.py"
    alias.write_text('"""Old name."""\nfrom .new import f, g  # noqa\n\n__all__ = ["f", "g"]\n_h = g\n')
    real = tmp_path / "real.py"
    real.write_text('"""Real."""\nfrom .new import f\n\n\ndef h():\n    return f()\n')
    assert only_reexports(alias) and not only_reexports(real)
