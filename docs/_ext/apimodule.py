"""Sphinx directive ``api-entry``: document a public name when it exists, say so when it does not yet.

Usage::

    .. api-entry:: simfab.couple
    .. api-entry:: simfab.coupling.run
       :kind: function

``kind`` is ``module`` (default: ``automodule`` with its members) or ``function`` / ``class``
(``autofunction`` / ``autoclass``). A name that cannot be imported renders as a short note naming
it (no warning): the public API is being merged area by area, and the reference fills in as it
lands. Every page listing names that are missing is printed at the end of the build
(``api-entry: waiting for ...``), so the integrator sees what the merged API must add.
"""

from __future__ import annotations

import importlib

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

LOG = logging.getLogger(__name__)
MISSING: dict[str, list[str]] = {}


def resolve(name: str):
    """The object named ``name`` (a module, or an attribute of one), or None."""
    try:
        return importlib.import_module(name)
    except ImportError:
        pass
    mod, _, attr = name.rpartition(".")
    try:
        return getattr(importlib.import_module(mod), attr, None) if mod else None
    except ImportError:
        return None


class ApiEntry(SphinxDirective):
    required_arguments = 1
    option_spec = {"kind": directives.unchanged}

    def run(self):
        name = self.arguments[0]
        kind = self.options.get("kind", "module")
        obj = resolve(name)
        if kind == "function" and (obj is None or not callable(obj) or isinstance(obj, type)):
            obj = None  # e.g. simfab.deploy.surface is still a module, not the command's function
        if obj is None:
            MISSING.setdefault(self.env.docname, []).append(name)
            para = nodes.paragraph()
            para += nodes.literal(text=name)
            para += nodes.Text(" - not in this build yet (part of the public API being merged).")
            return [nodes.note("", para)]
        directive = {"module": "automodule", "function": "autofunction", "class": "autoclass"}[kind]
        lines = [f".. {directive}:: {name}"]
        if kind in ("module", "class"):
            lines += ["   :members:"]
        node = nodes.section()
        node.document = self.state.document
        self.state.nested_parse(StringList(lines, source=self.env.docname), self.content_offset, node)
        return node.children


def report(app, exc):
    for doc, names in sorted(MISSING.items()):
        LOG.info(f"api-entry: waiting for {', '.join(sorted(set(names)))} ({doc})")


def setup(app):
    app.add_directive("api-entry", ApiEntry)
    app.connect("build-finished", report)
    return {"version": "1", "parallel_read_safe": False, "parallel_write_safe": True}
