"""Math as MathML, rendered by the browser itself: the docs need no MathJax download and read
the same offline.

Sphinx's default (``sphinx.ext.mathjax``) loads MathJax from a CDN, so an offline reader sees
raw LaTeX. No LaTeX (``sphinx.ext.imgmath`` needs latex and dvipng) and no local MathJax copy
were available where the docs are built, so this renderer converts each formula with docutils'
own LaTeX-to-MathML converter (``docutils.utils.math.latex2mathml``, part of Sphinx's
dependencies) into MathML, which current browsers display natively. A formula the converter
cannot read is a build warning (an error under ``sphinx -W``), shown as its LaTeX source.
"""

from __future__ import annotations

import re
from typing import Any

from docutils import nodes
from docutils.utils.math import latex2mathml
from sphinx.util import logging
from sphinx.util.math import get_node_equation_number

logger = logging.getLogger(__name__)

# Commands the converter lacks, rewritten to ones it has (same rendering).
_REWRITES = [
    (re.compile(r"\\(big|Big|bigg|Bigg)(?=\s*[\[(]|\s*\\\{|\s*\\lVert|\s*\\langle)"), r"\\\1l"),
    (re.compile(r"\\(big|Big|bigg|Bigg)(?=\s*[\])]|\s*\\\}|\s*\\rVert|\s*\\rangle)"), r"\\\1r"),
    (re.compile(r"\\dots(?![a-z])"), r"\\ldots"),
]


def _normalise(latex: str) -> str:
    for pattern, replacement in _REWRITES:
        latex = pattern.sub(replacement, latex)
    return latex.strip()


def _mathml(self: Any, node: nodes.Element, latex: str, block: bool) -> str:
    try:
        return latex2mathml.tex2mathml(_normalise(latex), as_block=block)
    except Exception as exc:  # the converter raises SyntaxError and friends
        logger.warning("math not converted to MathML (%s): %s", exc, latex, location=node)
        return f'<code class="math-source">{self.encode(latex)}</code>'


def visit_math(self: Any, node: nodes.Element) -> None:
    self.body.append(f'<span class="math">{_mathml(self, node, node.astext(), False)}</span>')
    raise nodes.SkipNode


def visit_displaymath(self: Any, node: nodes.Element) -> None:
    self.body.append(self.starttag(node, "div", CLASS="math"))
    if node["number"]:
        number = get_node_equation_number(self, node)
        self.body.append(f'<span class="eqno">({number})')
        self.add_permalink_ref(node, "Link to this equation")
        self.body.append("</span>")
    parts = [node.astext()] if node.get("nowrap") else [p for p in node.astext().split("\n\n") if p.strip()]
    for part in parts:
        self.body.append(_mathml(self, node, part, True))
    self.body.append("</div>\n")
    raise nodes.SkipNode


def setup(app: Any) -> dict[str, Any]:
    app.add_html_math_renderer("mathml", (visit_math, None), (visit_displaymath, None))
    return {"parallel_read_safe": True, "parallel_write_safe": True}
