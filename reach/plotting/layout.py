"""Fitting a picture's text to its figure: a title wrapped (and if need be shrunk) to the width of
its axes, and a legend placed below the axes, under the x-axis label, where it covers no data,
in as many columns as fit the figure's width.

Text is measured as matplotlib renders it (:meth:`matplotlib.text.Text.get_window_extent` with the
figure's renderer), so the wrap holds for any font and figure size. With a layout engine
(``layout="constrained"``) the axes shrink to leave room for the title and the legend; a figure
this module owns may also grow taller so that a long legend does not squeeze the axes.
"""

from __future__ import annotations

import re

MIN_FONT = 5.0         # points: text is shrunk no further (it wraps first)
MIN_AXES_HEIGHT = 4.6  # inches the axes keep when the figure may grow
MAX_HEIGHT = 16.0      # inches a growing figure reaches at most
PAD = 4.0              # points between the x-axis label and the legend


def _width(artist, text: str, renderer) -> float:
    artist.set_text(text)
    return artist.get_window_extent(renderer).width


def _pieces(artist, word: str, width: float, renderer) -> list[str]:
    """``word`` cut into the longest runs of characters that fit ``width`` (at least one each)."""
    out = []
    while word:
        lo, hi = 1, len(word)              # the longest prefix that fits: by bisection
        while lo < hi:
            mid = (lo + hi + 1) // 2
            if _width(artist, word[:mid], renderer) <= width:
                lo = mid
            else:
                hi = mid - 1
        out.append(word[:lo])
        word = word[lo:]
    return out


def wrap(artist, text: str, width: float, renderer, cut: bool = False) -> str:
    """``text`` with its lines broken so that each renders (in ``artist``'s font) at most
    ``width`` pixels wide where it can: after ``, `` or ``; `` preferably, else at a space; a
    single word wider than ``width`` keeps its own line, or with ``cut`` is cut into pieces that
    fit. Leaves ``artist`` showing the result."""
    out = []
    for line in text.split("\n"):
        chunks = [c for c in re.split(r"(?<=[,;]) ", line)]
        words = []
        for chunk in chunks:
            if _width(artist, chunk, renderer) <= width:
                words.append(chunk)
            else:
                for word in chunk.split(" "):
                    if cut and _width(artist, word, renderer) > width:
                        words += _pieces(artist, word, width, renderer)
                    else:
                        words.append(word)
        current = ""
        for word in words:
            trial = f"{current} {word}" if current else word
            if current and _width(artist, trial, renderer) > width:
                out.append(current)
                current = word
            else:
                current = trial
        out.append(current)
    result = "\n".join(out)
    artist.set_text(result)
    return result


def fit_text(artist, text: str, width: float, renderer) -> None:
    """Wrap ``text`` into ``artist`` to ``width`` pixels, shrinking its font (to ``MIN_FONT``)
    while a line is still wider, and at that size cutting words that are."""
    while True:
        wrap(artist, text, width, renderer)
        if artist.get_window_extent(renderer).width <= width:
            return
        if artist.get_fontsize() <= MIN_FONT:
            wrap(artist, text, width, renderer, cut=True)
            return
        artist.set_fontsize(max(MIN_FONT, artist.get_fontsize() - 0.5))


def _relayout(fig) -> None:
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)


def _below_axes(ax, renderer) -> float:
    """Pixels from the bottom of ``ax`` to the bottom of its x axis (tick labels and label)."""
    box = ax.xaxis.get_tightbbox(renderer)
    return 0.0 if box is None else max(0.0, ax.bbox.y0 - box.y0)


def legend_below(ax, handles, labels, fontsize: float = 7, title: str | None = None, renderer=None):
    """A legend of ``handles`` under ``ax``'s x-axis label (outside the axes, so over no data),
    centred on the axes and within the figure's width: of 1 to 4 columns, the lowest legend, its
    ``labels`` (and ``title``) wrapped to the width of a column."""
    from matplotlib.text import Text
    from matplotlib.transforms import ScaledTranslation

    fig = ax.figure
    renderer = renderer or fig.canvas.get_renderer()
    drop = (_below_axes(ax, renderer) + PAD * fig.dpi / 72) / fig.dpi          # inches
    where = ax.transAxes + ScaledTranslation(0, -drop, fig.dpi_scale_trans)
    centre = (ax.bbox.x0 + ax.bbox.x1) / 2
    room = 2 * min(centre - fig.bbox.x0, fig.bbox.x1 - centre) - 8
    em = fontsize * fig.dpi / 72
    probe = Text(0, 0, "", fontsize=fontsize, figure=fig)

    def build(ncols):
        column = (room - 2 * em) / ncols - 4.8 * em     # handle, its gap and the column spacing
        for h, label in zip(handles, labels):
            h.set_label(wrap(probe, label, column, renderer))
        head = wrap(probe, title, room - 2 * em, renderer) if title else None
        return ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=where,
                         ncols=ncols, fontsize=fontsize, title=head, title_fontsize=fontsize, framealpha=0.85,
                         borderaxespad=0.0)

    best, lowest = 1, None
    for ncols in range(1, min(4, max(1, len(handles))) + 1):
        box = build(ncols).get_window_extent(renderer)
        if box.width <= room and (lowest is None or box.height < lowest - 0.5 * em):
            best, lowest = ncols, box.height
    return build(best)


def arrange(ax, title: str, handles, title_size: float = 9, legend_size: float = 7,
            legend_title: str | None = None, grow: bool = False):
    """Set ``ax``'s title (wrapped to the axes' width) and a legend below the axes (see
    :func:`legend_below`; none without handles or ``legend_title``); with ``grow`` (the figure
    is the picture's own) the figure grows taller so the axes keep ``MIN_AXES_HEIGHT``. Runs the
    figure's layout engine, if any, so the extents measured are those saved. Returns the
    legend."""
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    labels = [h.get_label() for h in handles]
    ax.set_title("")
    _relayout(fig)
    heading = ax.set_title(title, fontsize=title_size)
    fit_text(heading, title, ax.bbox.width, renderer)
    legend = None
    if handles or legend_title:
        legend = legend_below(ax, handles, labels, legend_size, legend_title, renderer)
    if grow:                        # room for the axes, title, x axis and legend, stacked
        need = (MIN_AXES_HEIGHT * fig.dpi + heading.get_window_extent(renderer).height + _below_axes(ax, renderer)
                + (legend.get_window_extent(renderer).height + PAD * fig.dpi / 72 if legend else 0.0)
                + 0.5 * fig.dpi) / fig.dpi
        if need > fig.get_figheight():
            fig.set_figheight(min(MAX_HEIGHT, need))
    _relayout(fig)
    if grow and ax.bbox.height < MIN_AXES_HEIGHT * fig.dpi:
        fig.set_figheight(min(MAX_HEIGHT, fig.get_figheight() + MIN_AXES_HEIGHT - ax.bbox.height / fig.dpi))
        _relayout(fig)
    # the title may sit over a narrower axes now (a layout engine gave room to the legend)
    if heading.get_window_extent(renderer).width > ax.bbox.width:
        fit_text(heading, title, ax.bbox.width, renderer)
        _relayout(fig)
    if legend is not None:          # the x axis below the axes is measured in the final layout
        legend.remove()
        legend = legend_below(ax, handles, labels, legend_size, legend_title, renderer)
        _relayout(fig)
    return legend
