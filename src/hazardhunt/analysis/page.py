"""The report's HTML page: its sections as blocks of content (a paragraph, a heading, commands,
an image, a table), which a Jinja2 template (``templates/report.html.j2`` with
``templates/report.css``) turns into one self-contained page, escaping every text it is given.

Only :class:`Prose` carries markup of its own (numbers in bold, a command in ``<code>``); it is
built with :func:`markupsafe.escape` around every value it shows.
"""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import jinja2
import pandas as pd
from markupsafe import Markup

from hazardhunt.errors import InputError
from hazardhunt.warning_lines import printable


@dataclass(frozen=True)
class Text:
    """A paragraph of plain text."""

    text: str
    style: str = ""
    """A CSS class: ``warning``, ``headline`` or none."""
    kind: ClassVar[str] = "text"


@dataclass(frozen=True)
class Prose:
    """A paragraph with inline markup, every value in it escaped where it was built."""

    markup: Markup
    style: str = ""
    kind: ClassVar[str] = "markup"


@dataclass(frozen=True)
class Heading:
    """A heading inside a section."""

    text: str
    kind: ClassVar[str] = "heading"


@dataclass(frozen=True)
class Commands:
    """Shell commands, one per line."""

    lines: tuple[str, ...]
    kind: ClassVar[str] = "commands"


@dataclass(frozen=True)
class Image:
    """A picture, inlined so that the page opens offline."""

    mime: str
    data: str
    """The file's bytes in base64."""
    caption: str
    kind: ClassVar[str] = "image"


@dataclass(frozen=True)
class Table:
    """A table, with a link to its CSV file beside the page."""

    name: str
    html: Markup
    caption: str
    kind: ClassVar[str] = "table"


Block = Text | Prose | Heading | Commands | Image | Table
"""What a section holds."""


@dataclass
class Section:
    """One section of the page: a title, a sentence that says what it shows, its blocks."""

    title: str
    intro: str = ""
    blocks: list[Block] = field(default_factory=list)


def image(path: Path, caption: str) -> Image:
    """The picture written at ``path`` (PNG or GIF), to inline."""
    mime = "image/gif" if path.suffix == ".gif" else "image/png"
    return Image(mime, base64.b64encode(path.read_bytes()).decode(), caption)


def table(name: str, data: pd.DataFrame, caption: str = "") -> Table:
    """``data`` as an HTML table, numbers to four significant digits."""
    shown = data.to_html(index=False, float_format=_number, border=0, na_rep="")
    return Table(name, Markup(shown), caption)


_ENVIRONMENT = jinja2.Environment(
    loader=jinja2.PackageLoader("hazardhunt.analysis", "templates"),
    autoescape=True,
    undefined=jinja2.StrictUndefined,
)


def render_page(
    directory: Path, opening: Section | None, sections: list[Section], facts: str
) -> str:
    """The whole page: ``opening`` (the verdict) first, then ``facts``, the contents and
    every section."""
    return _ENVIRONMENT.get_template("report.html.j2").render(
        name=directory.name,
        directory=str(directory),
        opening=opening,
        sections=sections,
        facts=facts,
    )


def check_report_folder(folder: Path) -> None:
    """Raises InputError if the report's folder ``folder`` is a symbolic link: a report
    replaces its own folder, and never writes through a link found in received results."""
    if folder.is_symlink():
        raise InputError(
            f"{folder}: a symbolic link, where the report's own folder goes; a report never "
            "writes through one: remove the link (nothing was written)"
        )


def markdown_table(data: pd.DataFrame) -> str:
    """A table in GitHub Markdown, numbers to four significant digits. Text is shown as text:
    names from results (a tester's, a class's) may be anyone's, and ``<script>``, a ``|`` or
    a line break in one neither runs, nor splits its cell, nor ends its row."""
    header = "| " + " | ".join(_markdown_cell(str(c)) for c in data.columns) + " |"
    rule = "|" + "|".join("---" for _ in data.columns) + "|"
    lines = [header, rule]
    for row in data.itertuples(index=False):
        cells = [_number(v) if isinstance(v, float) else str(v) for v in row]
        lines.append("| " + " | ".join(_markdown_cell(c) for c in cells) + " |")
    return "\n".join(lines)


def _markdown_cell(text: str) -> str:
    """``text`` as the text of one cell of a Markdown table: HTML escaped (``&lt;script&gt;``),
    ``|`` escaped by a backslash, control characters and line breaks written out (``\\x1b``)."""
    return html.escape(printable(text), quote=False).replace("|", "\\|")


def _number(value: float) -> str:
    return "" if pd.isna(value) else f"{value:.4g}"
