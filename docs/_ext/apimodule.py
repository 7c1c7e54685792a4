"""Sphinx directive ``api-entry``: document a public name of the API; a name that does not exist fails the build.

Usage::

    .. api-entry:: simfab.couple
    .. api-entry:: simfab.coupling.run
       :kind: function

``kind`` is ``module`` (default: ``automodule`` with its members) or ``function`` / ``class``
(``autofunction`` / ``autoclass``). A name that cannot be imported, or is not of its kind, is a
Sphinx warning (an error under ``-W``, as CI builds): the reference cannot silently lose an entry.
"""

from __future__ import annotations

import importlib

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

LOG = logging.getLogger(__name__)


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
            obj = None
        if obj is None:
            LOG.warning(f"api-entry: {name} is not a public {kind} of simfab", location=self.get_location())
            return []
        directive = {"module": "automodule", "function": "autofunction", "class": "autoclass"}[kind]
        lines = [f".. {directive}:: {name}"]
        if kind in ("module", "class"):
            lines += ["   :members:"]
        node = nodes.section()
        node.document = self.state.document
        self.state.nested_parse(StringList(lines, source=self.env.docname), self.content_offset, node)
        return node.children


def setup(app):
    app.add_directive("api-entry", ApiEntry)
    return {"version": "1", "parallel_read_safe": False, "parallel_write_safe": True}
