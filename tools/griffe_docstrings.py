"""A Griffe extension for the documentation site (mkdocs.yml): docstrings written for ``help()`` and Sphinx, read
as Markdown.

The docstrings are numpydoc with reStructuredText roles (``:func:`simulate```, ``:class:`~ddtrack.errors.ConfigError```)
and units in brackets after a vector (``[v, omega] [m/s, rad/s]``). On the site, a role becomes its name in code,
linked to its page where the name is documented there (an optional cross-reference: no link, no warning when it is
not), and the bracket after ``] `` is escaped so that Python-Markdown does not read ``[a] [b]`` as a reference link.
The source is not changed.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

import ddtrack

ROLE = re.compile(r":(?:py:)?(?:func|class|meth|attr|data|const|exc|mod|obj):`(~?)([\w.]+)(?:\(\))?`")
REFERENCE_LIKE = re.compile(r"\] \[")
LITERAL_BLOCK = re.compile(r"(\S)::\n\n")
# import ddtrack exposes these lazily; point them at the module that defines them (import ddtrack is light)
TOP_LEVEL = ddtrack._SOURCES


def _target(obj: griffe.Object, name: str) -> str:
    head, _, rest = name.partition(".")
    if head == "ddtrack" and rest in TOP_LEVEL:
        return f"ddtrack.{TOP_LEVEL[rest]}.{rest}"
    if head == "ddtrack":
        return name
    try:
        return obj.resolve(head) + (f".{rest}" if rest else "")
    except (griffe.NameResolutionError, griffe.AliasResolutionError, griffe.CyclicAliasError):  # stays unlinked
        return name


def _markdown(obj: griffe.Object, text: str) -> str:
    def role(match: re.Match[str]) -> str:
        tilde, name = match.groups()
        shown = name.rsplit(".", 1)[-1] if tilde else name
        return f'<autoref identifier="{_target(obj, name)}" optional><code>{shown}</code></autoref>'

    text = ROLE.sub(role, text)
    text = REFERENCE_LIKE.sub("] \\\\[", text)
    return LITERAL_BLOCK.sub(r"\1:\n\n", text)


class DocstringsAsMarkdown(griffe.Extension):
    """Rewrite every docstring of the package once it is loaded."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        seen: set[str] = set()

        def visit(obj: griffe.Object) -> None:
            if obj.path in seen:
                return
            seen.add(obj.path)
            if obj.docstring is not None:
                obj.docstring.value = _markdown(obj, obj.docstring.value)
            for member in obj.members.values():
                if not member.is_alias:
                    visit(member)

        visit(pkg)
