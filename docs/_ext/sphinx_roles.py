"""Griffe extension for the API reference: the docstrings use Sphinx roles (:func:`x`, :class:`x`, ...),
which mkdocstrings would print literally; they are shown as inline code `x` instead (mkdocs.yml loads it)."""
from __future__ import annotations

import re

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|const|term|ref):`~?([^`]+)`")


class SphinxRoles(griffe.Extension):
    """Replace Sphinx cross-reference roles in every docstring by inline code."""

    def on_object(self, *, obj, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(r"`\1`", obj.docstring.value)
