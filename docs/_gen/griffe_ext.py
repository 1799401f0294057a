"""Griffe extensions for the API reference (mkdocs.yml: mkdocstrings' ``extensions``).

:class:`LazyExports`: a package's ``__all__`` names that it imports lazily (PEP 562
``__getattr__``, as :mod:`planner.problems` does) are shown as the objects they name.

:class:`RstRoles`: the docstrings' reST roles as mkdocstrings cross-references.

The docstrings name other objects as reST does (``:func:`plan_walk```,
``:class:`~planner.world.terrain.Terrain```, ``:meth:`LocalPlanner.level_under```). Markdown
would show the role as text; this turns each into a link
(``[`plan_walk`][planner.planning.walk.plan_walk]``) when the name resolves to an object
that the API reference renders: the name itself, then relative to the docstring's class,
module and packages, then names the module imports, then a unique ending of a path in the
package. A name that does not resolve (an object outside the package, a private one)
becomes plain code. The links are checked by the strict build.
"""

from __future__ import annotations

import re
from collections import defaultdict
from typing import Any

import griffe

ROLE = re.compile(
    r":(?:py:)?(?:class|func|mod|meth|attr|data|const|exc|obj):`(~?)([^`<>]+?)(\(\))?`"
)


def _walk(obj: griffe.Object):
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _walk(member)


def _rendered(obj: Any) -> bool:
    """Whether the API reference shows ``obj`` (its pages show public members only)."""
    if obj.is_alias:
        return False
    if obj.is_module:
        return True
    if obj.parent is None or not _rendered(obj.parent):
        return False
    try:
        return bool(obj.is_public)
    except Exception:  # noqa: BLE001  (an unresolved alias in __all__)
        return False


class LazyExports(griffe.Extension):
    """Members for ``__all__`` names a module neither defines nor imports (PEP 562 exports).

    Each becomes an alias of the one public object of that name in the module's subpackages.
    """

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        """Add the missing exports of every module of the package as aliases."""
        modules = [o for o in _walk(pkg) if o.is_module]
        for module in modules:
            for name in map(str, module.exports or ()):
                if name in module.members:
                    continue
                found = [
                    o
                    for o in _walk(module)
                    if o.name == name and o.parent is not None and o.parent.is_module
                    and o.parent is not module and _rendered(o)
                ]  # fmt: skip
                if len(found) == 1:
                    module.set_member(name, griffe.Alias(name, found[0].path, parent=module))


class RstRoles(griffe.Extension):
    """Rewrite reST roles in every docstring of the package into cross-references."""

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        """Rewrite the whole package once it is loaded."""
        self.collection = loader.modules_collection
        self.by_suffix: dict[str, list[str]] = defaultdict(list)
        objects = list(_walk(pkg))
        for obj in objects:
            parts = obj.path.split(".")
            for k in range(1, min(4, len(parts)) + 1):
                self.by_suffix[".".join(parts[-k:])].append(obj.path)
        for obj in objects:
            if obj.docstring is not None and ":" in obj.docstring.value:
                obj.docstring.value = ROLE.sub(
                    lambda m, o=obj: self._link(o, m), obj.docstring.value
                )

    def _get(self, path: str):
        try:
            obj = self.collection.get_member(path)
        except Exception:  # noqa: BLE001  (not there, or an alias that does not resolve)
            obj = self._inherited(path)
        if obj is None:
            return None
        try:
            while obj is not None and obj.is_alias:
                obj = obj.final_target
        except Exception:  # noqa: BLE001
            return None
        return obj

    def _inherited(self, path: str):
        """``Class.member`` where the class inherits the member (its base class's object)."""
        owner, _, name = path.rpartition(".")
        try:
            cls = self.collection.get_member(owner)
            while cls.is_alias:
                cls = cls.final_target
            return cls.all_members.get(name) if cls.is_class else None
        except Exception:  # noqa: BLE001
            return None

    def _resolve(self, where: griffe.Object, name: str):
        candidates = [name]
        scope = where
        while scope is not None:
            candidates.append(f"{scope.path}.{name}")
            scope = scope.parent
        module = where.module
        head, _, rest = name.partition(".")
        imported = module.members.get(head)
        if imported is not None and imported.is_alias:
            candidates.append(imported.target_path + (f".{rest}" if rest else ""))
        for path in candidates:
            obj = self._get(path)
            if obj is not None:
                return obj
        found = self.by_suffix.get(name, [])
        if len(found) == 1:
            return self._get(found[0])
        return None

    def _link(self, where: griffe.Object, m: re.Match) -> str:
        tilde, name, call = m.group(1), m.group(2).strip(), m.group(3) or ""
        shown = (name.rsplit(".", 1)[-1] if tilde else name) + call
        obj = self._resolve(where, name)
        if obj is None or not _rendered(obj):
            return f"`{shown}`"
        return f"[`{shown}`][{obj.path}]"
