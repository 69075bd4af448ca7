"""The HTML pages (``labrig report``, ``diagnosis.html``, ``fleet.html``) are jinja2 templates in
``labrig/report/templates/``: a page's layout and wording live there, its numbers and figures
come from Python. Every value is escaped (autoescape on); a template that names a value the
page does not give is an error (``StrictUndefined``), not a silent blank.

A lab restyles its reports by editing the templates (``style.css`` is the style sheet every page
includes), or without touching the installation by putting templates of the same names in a
folder named by the environment variable ``LABRIG_TEMPLATES``: those are used first.
"""

from __future__ import annotations

import base64
import functools
import math
import os
from typing import Any

import jinja2
from markupsafe import Markup

__all__ = ["TEMPLATES_ENV", "data_uri", "environment", "render", "sig"]

#: environment variable naming a folder of templates used before the package's
TEMPLATES_ENV = "LABRIG_TEMPLATES"


def data_uri(png: bytes) -> str:
    """The PNG ``png`` as a ``data:`` URI."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def sig(v: float | None, digits: int = 4) -> str:
    """``digits`` significant digits, scientific when tiny or huge, ``—`` when undefined."""
    if v is None or not math.isfinite(v):
        return "—"
    if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
        return f"{v:.{digits - 1}e}"
    return f"{v:.{digits}g}"


def _img(png: bytes | None, alt: str) -> Markup:
    """An ``<img>`` of ``png`` inlined as a data URI (nothing without a figure)."""
    if png is None:
        return Markup("")
    return Markup('<img src="{}" alt="{}">').format(data_uri(png), alt)


@functools.cache
def _environment(override: str) -> jinja2.Environment:
    loaders: list[jinja2.BaseLoader] = [jinja2.PackageLoader("labrig.report", "templates")]
    if override:
        loaders.insert(0, jinja2.FileSystemLoader(override))
    env = jinja2.Environment(
        loader=jinja2.ChoiceLoader(loaders),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters["sig"] = sig
    env.filters["img"] = _img
    env.globals["img"] = _img
    return env


def environment() -> jinja2.Environment:
    """The templates' environment (the ``LABRIG_TEMPLATES`` folder first, when set)."""
    return _environment(os.environ.get(TEMPLATES_ENV, ""))


def render(name: str, **context: Any) -> str:
    """The template ``name`` rendered with ``context``."""
    return environment().get_template(name).render(**context)
