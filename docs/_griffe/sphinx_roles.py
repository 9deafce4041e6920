"""Griffe extension of the docs build: the docstrings' Sphinx roles become cross-references.

The docstrings name other objects with Sphinx roles (``:class:`~agents.search.execution.safety.SafetyLayer```,
``:meth:`plan```, ``:func:``, ``:attr:``, ``:mod:``, ``:data:``, ...), which read well in
``help()``. mkdocstrings reads Markdown, where a role would stay literal text, so this extension
rewrites every docstring of the documented packages, once they are loaded and before
mkdocstrings parses them, into Markdown:

- a role whose target the API reference documents becomes an autorefs cross-reference,
  ``[`SafetyLayer`][agents.search.execution.safety.SafetyLayer]``;
- any other role becomes code text (``SafetyLayer``): objects of other libraries (numpy, torch,
  gymnasium, stable-baselines3, ...) and objects of the packages the reference does not show.

A target resolves much as Sphinx resolves it: a dotted path as written, else its first name in
the scope of the docstring's object (its members, inherited ones too, those of its class and
module, the module's imports). A class, function or module name found in no scope links to the
one documented object of that name, if only one has it; a bare method or attribute name does not
(another class's member of that name would be the wrong object). A link goes to the anchor
mkdocstrings gives the object: where it is defined when that module is documented, else the
module that exports it. ``~`` shows the last component, ``:meth:``/``:func:`` add ``()``,
``title <target>`` shows the title and ``!target`` stays code text.

The documented objects are those the ``::: identifier`` lines of ``docs/api/*.md`` render under
the handler options of ``mkdocs.yml``: the identifier itself, and below it the members that are
not inherited, whose name has no leading underscore, that have a docstring (or a member with
one) and that are not imported unless public. Submodules of a documented module are not shown.

The extension loads every package the API pages name into the same collection, so references
between the packages resolve wherever loading starts.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Optional, Tuple, Union

from griffe import (
    Alias,
    AliasResolutionError,
    CyclicAliasError,
    Extension,
    GriffeLoader,
    Module,
    Object,
)

API_PAGES = Path(__file__).resolve().parents[1] / "api"

#: a role in docstring text: ``:kind:`body``` (``:py:kind:`` too); the body may span lines
ROLE = re.compile(r":(?:py:)?(?P<kind>[a-z]+):`(?P<body>[^`]+)`")
#: an explicit title: ``title <target>``
TITLED = re.compile(r"(?P<title>.*?)\s*<(?P<target>[^<>]+)>\s*", re.S)
#: the kinds that name a member of a class
MEMBER_KINDS = ("meth", "attr")
#: the kinds whose title gets ``()``
CALLABLE_KINDS = ("meth", "func")
#: a ``::: identifier`` line of an API page
DIRECTIVE = re.compile(r"^:::\s+(?P<identifier>[\w.]+)\s*$")

AnyObject = Union[Object, Alias]


def api_identifiers(pages: Path = API_PAGES) -> List[str]:
    """The identifiers of the ``::: identifier`` lines of the API pages, in page order.

    Raises:
        ValueError: A directive carries its own options (indented lines below it), which the
            documented objects computed here would not follow.
    """
    identifiers = []
    for page in sorted(pages.glob("*.md")):
        lines = page.read_text(encoding="utf-8").splitlines()
        for number, line in enumerate(lines):
            match = DIRECTIVE.match(line)
            if not match:
                continue
            if number + 1 < len(lines) and lines[number + 1][:1] in (" ", "\t"):
                raise ValueError(f"{page.name}:{number + 1}: '::: {match['identifier']}' has options")
            identifiers.append(match["identifier"])
    return identifiers


def _rendered_members(obj: AnyObject) -> Iterator[AnyObject]:
    """The members mkdocstrings renders below a rendered object (see the module docstring)."""
    for member in list(obj.members.values()):
        try:
            if member.is_module or member.name.startswith("_"):
                continue
            if member.is_alias and not member.is_public:
                continue
            if not member.has_docstrings:
                continue
        except (AliasResolutionError, CyclicAliasError):
            continue
        yield member


def documented_anchors(collection: Any, identifiers: Iterable[str]) -> Dict[str, str]:
    """Canonical path -> anchor (the path mkdocstrings renders it under) of every object the API
    pages document; an object that is also shown where it is defined links there."""
    anchors: Dict[str, str] = {}

    def visit(obj: AnyObject) -> None:
        try:
            canonical = obj.canonical_path
        except (AliasResolutionError, CyclicAliasError):
            return
        anchor = anchors.get(canonical)
        if anchor == canonical or (anchor is not None and obj.path != canonical):
            return  # shown twice: where it is defined, else where first shown
        anchors[canonical] = obj.path
        if obj.is_module or obj.is_class:
            for member in _rendered_members(obj):
                visit(member)

    for identifier in identifiers:
        visit(collection[identifier])
    return anchors


class Resolver:
    """Turns role targets into the anchors of documented objects, from one docstring's scope."""

    def __init__(self, collection: Any, anchors: Dict[str, str]):
        self.collection = collection
        self.anchors = anchors
        #: last name -> (canonical path, anchor) of the documented objects of that name
        self.by_name: Dict[str, List[Tuple[str, str]]] = {}
        for canonical, anchor in sorted(anchors.items()):
            self.by_name.setdefault(canonical.rsplit(".", 1)[-1], []).append((canonical, anchor))

    def _lookup(self, path: str) -> Optional[str]:
        """The anchor of the object at ``path`` where it is documented, else None."""
        try:
            return self.anchors.get(self.collection[path].canonical_path)
        except (KeyError, AliasResolutionError, CyclicAliasError, ValueError):
            return None

    def _exists(self, path: str) -> bool:
        try:
            self.collection[path]
        except (KeyError, AliasResolutionError, CyclicAliasError, ValueError):
            return False
        return True

    def resolve(self, target: str, scope: AnyObject, kind: str = "obj") -> Optional[str]:
        """The anchor of the documented object ``target`` names in the scope of ``scope``, else None.

        ``kind`` is the role's: a bare method or attribute name found in no scope stays unlinked
        (another class's member of that name would be the wrong object).
        """
        target = target.lstrip(".")
        head, _, rest = target.partition(".")
        if self._exists(target):
            return self._lookup(target)
        base = self._in_scope(head, scope)
        if base is None:
            return None if kind in MEMBER_KINDS and not rest else self._only(target, "")
        full = f"{base}.{rest}" if rest else base
        if self._exists(full):
            return self._lookup(full)
        # a name a package exports lazily (``agents.SafeGoalTD3``, from a module ``__getattr__``):
        # the one documented object of that name below the deepest module of the path
        module = full.rsplit(".", 1)[0]
        while module and not (self._exists(module) and self.collection[module].is_module):
            module = module.rpartition(".")[0]
        return self._only(full.rsplit(".", 1)[-1], module + ".") if module else None

    def _in_scope(self, name: str, scope: AnyObject) -> Optional[str]:
        """The path ``name`` stands for in ``scope``: a member (inherited ones too) of ``scope`` or
        of an enclosing object, an import of the module, an enclosing class itself or a loaded
        top-level package."""
        obj: Optional[AnyObject] = scope
        try:
            while obj is not None:
                members = obj.all_members if obj.is_class else obj.members
                if name in members:
                    member = members[name]
                    return member.target_path if isinstance(member, Alias) and not member.inherited else member.path
                if obj.name == name and not obj.is_module:
                    return obj.path
                obj = obj.parent
        except (AliasResolutionError, CyclicAliasError):
            return None
        return name if name in self.collection else None  # a top-level package

    def _only(self, tail: str, prefix: str) -> Optional[str]:
        """The anchor of the one documented object whose path starts with ``prefix`` and ends
        with ``.tail``, else None."""
        matches = [anchor for canonical, anchor in self.by_name.get(tail.rsplit(".", 1)[-1], [])
                   if any(path.endswith("." + tail) and path.startswith(prefix) for path in (canonical, anchor))]
        return matches[0] if len(matches) == 1 else None


def _reference(match: "re.Match[str]", scope: AnyObject, resolver: Resolver) -> str:
    """The Markdown for one role: a cross-reference, or code text."""
    kind, body = match["kind"], " ".join(match["body"].split())
    titled = TITLED.fullmatch(body)
    if titled:
        title, target = titled["title"], titled["target"].strip()
    else:
        target = body
        suppress, short = target.startswith("!"), target.lstrip("!").startswith("~")
        target = target.lstrip("!~")
        title = target.rsplit(".", 1)[-1] if short else target.lstrip(".")
        if kind in CALLABLE_KINDS and not title.endswith(")"):
            title += "()"
        if suppress:
            return f"`{title}`"
    target = target.lstrip("!~")
    if target.endswith("()"):
        target = target[:-2]
    path = resolver.resolve(target, scope, kind) if re.fullmatch(r"\.?[A-Za-z_][\w.]*", target) else None
    return f"[`{title}`][{path}]" if path else f"`{title}`"


def translate(text: str, scope: AnyObject, resolver: Resolver) -> str:
    """``text`` (a docstring) with every Sphinx role rewritten as a cross-reference or code text."""
    return ROLE.sub(lambda match: _reference(match, scope, resolver), text)


def _objects(obj: Object) -> Iterator[Object]:
    """``obj`` and every object defined below it (not imported ones)."""
    yield obj
    for member in list(obj.members.values()):
        if not member.is_alias:
            yield from _objects(member)  # type: ignore[arg-type]


def translate_packages(collection: Any, packages: Iterable[str], identifiers: Iterable[str]) -> None:
    """Rewrite, in place, the docstrings of every object defined in ``packages``."""
    resolver = Resolver(collection, documented_anchors(collection, identifiers))
    for name in packages:
        for obj in _objects(collection[name]):
            if obj.docstring is not None:
                obj.docstring.value = translate(obj.docstring.value, obj, resolver)


class SphinxRoles(Extension):
    """Rewrites the roles of every docstring of the packages the API pages document.

    The first of those packages to load loads the others into the same collection, then the
    docstrings of all of them are rewritten at once.
    """

    def __init__(self) -> None:
        super().__init__()
        self.identifiers = api_identifiers()
        self.packages = list(dict.fromkeys(identifier.split(".", 1)[0] for identifier in self.identifiers))
        self.busy = False
        self.done = False

    def on_package(self, *, pkg: Module, loader: GriffeLoader, **kwargs: Any) -> None:
        if self.busy or self.done or pkg.name not in self.packages:
            return
        self.busy = True
        try:
            for name in self.packages:
                if name not in loader.modules_collection:
                    loader.load(name)
            translate_packages(loader.modules_collection, self.packages, self.identifiers)
            self.done = True
        finally:
            self.busy = False
