"""Figures without pyplot: a library must not touch the user's pyplot state or backend.

``matplotlib.figure.Figure`` draws with its own Agg canvas (``savefig`` works with no
backend chosen), is garbage-collected like any object and never appears in a user's
``plt.show()``. Every figure of dicblur is made here.
"""

from __future__ import annotations

from typing import Any

__all__ = ["figure", "figure_axes", "subplots"]


def subplots(
    nrows: int = 1, ncols: int = 1, *, figsize: tuple[float, float] | None = None, **kwargs: Any
) -> tuple[Any, Any]:
    """``(Figure, axes)`` like ``pyplot.subplots``, but on a detached ``Figure``."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def figure(width: float, height: float) -> Any:
    """A detached ``Figure`` of ``width`` x ``height`` inches at 100 dpi (the reports' pages:
    the same pixels whatever the user's ``figure.dpi``)."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=100)


def figure_axes(width: float, height: float, **kwargs: Any) -> tuple[Any, Any]:
    """``(Figure, axes)``: a :func:`figure` with one axes (``kwargs`` go to
    ``add_subplot``, e.g. ``projection="3d"``)."""
    fig = figure(width, height)
    return fig, fig.add_subplot(1, 1, 1, **kwargs)
