"""MkDocs hook: the docstrings' Sphinx roles (``:func:`name```, ``:class:`~pkg.Name```) read
as plain code on the site, as they read in an editor; mkdocstrings renders the role's name
beside the code otherwise."""

from __future__ import annotations

import re

from mkdocs.structure.pages import Page

_ROLE = re.compile(r":(?:func|class|meth|mod|attr|data|exc|obj):<code>(~?)([^<]*)</code>")


def _code(match: re.Match[str]) -> str:
    short, target = match.group(1), match.group(2)
    return f"<code>{target.rsplit('.', 1)[-1] if short else target}</code>"


def on_page_content(html: str, page: Page, **_: object) -> str:
    return _ROLE.sub(_code, html)
