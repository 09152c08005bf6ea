"""Sphinx extension of the lecture site: a chapter's link to its assignment notebook becomes a download.

A chapter ends with an ordinary Markdown link to the notebook that exercises it, relative to the
chapter, e.g. ``[hw1_imitation.ipynb](../assignments/hw1_imitation/hw1_imitation.ipynb)``. JupyterLab
and GitHub open that link as it is. The site is built from ``lectures/`` only, so MyST would take
the link for a missing page (``.ipynb`` is a source suffix); this extension turns each such link,
while the chapter is read, into Sphinx's download reference: the notebook is copied into the site
(``_downloads/``) and the link fetches it there.
"""
from __future__ import annotations

import re

from docutils import nodes
from sphinx import addnodes
from sphinx.transforms import SphinxTransform

NOTEBOOK = re.compile(r"^(\.\./)+assignments/[\w-]+/[\w-]+(\.ipynb)?$")
"""What MyST makes of such a link: a reference to the document ``../assignments/<id>/<id>`` (suffix dropped)."""


class NotebookDownloads(SphinxTransform):
    """Each link to ``../assignments/<id>/<id>.ipynb`` a download reference (before the downloads are collected)."""

    default_priority = 700

    def apply(self, **kwargs) -> None:
        for xref in list(self.document.findall(addnodes.pending_xref)):
            target = xref.get("reftarget", "")
            if not NOTEBOOK.match(target):
                continue
            download = addnodes.download_reference("", "", refdoc=self.env.docname, reftype="download",
                                                   reftarget=target.removesuffix(".ipynb") + ".ipynb", refexplicit=True)
            download += nodes.inline("", xref.astext(), classes=["xref", "download"])
            xref.replace_self(download)


def setup(app):
    app.add_transform(NotebookDownloads)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
