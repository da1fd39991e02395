"""Which texts of a figure collide: the one check the figure tests share.

A tick label counts only where its tick lies inside its axis's view (matplotlib keeps the
others, visible and at stale positions, but does not draw them); tick labels of one axis are
not compared with each other (matplotlib spaces them itself). Insets count as axes.
"""

from __future__ import annotations

import itertools

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text


def collisions(fig: Figure, *, margin: float = 2.0, touching: bool = False, every: bool = False) -> list[tuple[str, str]]:
    """Pairs of visible, non-empty texts of ``fig`` whose drawn boxes overlap by more than
    ``margin`` pixels each way (``touching``: by ``margin`` or more, so with 0 boxes that touch
    count; ``every``: tick labels out of the view compared too)."""
    canvas = fig.canvas if hasattr(fig.canvas, "get_renderer") else FigureCanvasAgg(fig)  # a saved and closed figure lost its canvas
    canvas.draw()
    renderer = canvas.get_renderer()
    owner: dict[int, object] = {}  # tick label (or offset text) -> its axis
    hidden: set[int] = set()  # tick labels of ticks outside the view
    for ax in fig.findobj(Axes):
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            slack = 1e-9 * (hi - lo)
            for tick in [*axis.get_major_ticks(), *axis.get_minor_ticks()]:
                inside = lo - slack <= tick.get_loc() <= hi + slack
                for label in (tick.label1, tick.label2):
                    owner[id(label)] = axis
                    if not inside:
                        hidden.add(id(label))
            owner[id(axis.get_offset_text())] = axis
    texts = [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip() and (every or id(t) not in hidden)]
    boxes = [(t, owner.get(id(t)), t.get_window_extent(renderer)) for t in texts]
    found = []
    for (a, axis_a, box_a), (b, axis_b, box_b) in itertools.combinations(boxes, 2):
        if axis_a is not None and axis_a is axis_b:
            continue
        width = min(box_a.x1, box_b.x1) - max(box_a.x0, box_b.x0)
        height = min(box_a.y1, box_b.y1) - max(box_a.y0, box_b.y0)
        if (width >= margin and height >= margin) if touching else (width > margin and height > margin):
            found.append((a.get_text()[:50], b.get_text()[:50]))
    return found
