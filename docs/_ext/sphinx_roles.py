"""A griffe extension for the docs build: Sphinx cross-reference roles as inline code.

The package's numpydoc docstrings name other objects with Sphinx roles
(``:func:`~meshphase.io.read```); mkdocstrings renders docstrings as Markdown, where a role
would show as literal text. This extension rewrites each role to inline code before the
docstring is parsed: ``:func:`~meshphase.io.read``` becomes ```read```, ``:mod:`.io```
becomes ```.io```. The source files are not touched.
"""

from __future__ import annotations

import re

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const|ref|term):`(~?)([^`]+)`")


def plain_roles(text: str) -> str:
    """``text`` with every Sphinx role replaced by inline code of its target.

    Parameters
    ----------
    text : str
        A docstring.

    Returns
    -------
    str
        The same docstring; ``:role:`~a.b``` gives ```b``` and ``:role:`a.b``` gives ```a.b```.
    """
    def repl(m: re.Match) -> str:
        target = m.group(2)
        if m.group(1):
            target = target.rsplit(".", 1)[-1]
        return f"`{target}`"

    return ROLE.sub(repl, text)


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring griffe loads (:func:`plain_roles`)."""

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:  # noqa: D102
        if obj.docstring is not None:
            obj.docstring.value = plain_roles(obj.docstring.value)
