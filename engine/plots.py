"""The report's plots as inline SVG, drawn from numpy without matplotlib (whose import and drawing took 1.0-1.3 s
of a paper-scale run): histograms, bar charts and the cut panels. A cut panel's polygons are rasterised here
(2x supersampled, element edges darkened, a PNG of its own size whatever the element count) under vector axes,
ticks, colour bars and legends.
"""

from __future__ import annotations

import base64
import html
import math
import struct
import zlib

import numpy as np

FONT = 'font-family="sans-serif" font-size="12"'
CHAR = 7.0  # px: a generous width of one character at FONT, for the margins
MARK = "#cc3311"  # dashed limits and the finest element's cross
COLOURMAPS = {  # 17 colours of matplotlib's maps, interpolated linearly (within 6/255 of the originals)
    "viridis": "440154 48186a 472d7b 424086 3b528b 33638d 2c728e 26828e 21918c 1fa088 28ae80 3fbc73 5ec962 "
    "84d44b addc30 d8e219 fde725",
    "magma": "000004 0a0822 1d1147 36106b 51127c 6a1c81 832681 9c2e7f b73779 d0416f e75263 f56b5c fc8961 fea772 "
    "fec488 fde2a3 fcfdbf",
}


def colourmap(name: str, t: np.ndarray) -> np.ndarray:
    """(n, 3) uint8 colours of ``t`` in [0, 1] (clipped; NaN as 0)."""
    anchors = np.array([[int(c[i : i + 2], 16) for i in (0, 2, 4)] for c in COLOURMAPS[name].split()], dtype=float)
    x = np.clip(np.nan_to_num(np.asarray(t, dtype=float)), 0, 1) * (len(anchors) - 1)
    low = np.minimum(x.astype(int), len(anchors) - 2)
    f = (x - low)[:, None]
    return np.rint(anchors[low] * (1 - f) + anchors[low + 1] * f).astype(np.uint8)


def _text(x, y, label, anchor="middle", extra="") -> str:
    return f'<text x="{x:.1f}" y="{y:.1f}" text-anchor="{anchor}"{extra}>{html.escape(str(label))}</text>'


def _number(value: float) -> str:
    if value == round(value) and abs(value) < 1e7:
        return str(int(value))
    return f"{value:.4g}".replace("e+0", "e").replace("e-0", "e-")


def nice_ticks(low: float, high: float, count: int = 6) -> np.ndarray:
    """Round tick values (1, 2 or 5 x 10^k apart) within [low, high]."""
    if not high > low:
        return np.array([low])
    raw = (high - low) / count
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(s * power for s in (1, 2, 2.5, 5, 10) if s * power >= raw)
    ticks = np.arange(math.ceil(low / step - 1e-9), math.floor(high / step + 1e-9) + 1) * step
    return np.where(np.abs(ticks) < 1e-12 * step, 0.0, ticks)


class Axes:
    """A plot area (left, top, width, height in px) with data limits; y on a log scale if ``log``."""

    def __init__(self, left, top, width, height, xlim, ylim, log=False):
        self.left, self.top, self.width, self.height = left, top, width, height
        self.xlim, self.ylim, self.log = (float(xlim[0]), float(xlim[1])), (float(ylim[0]), float(ylim[1])), log

    def x(self, value):
        low, high = self.xlim
        return self.left + (np.asarray(value, dtype=float) - low) / ((high - low) or 1.0) * self.width

    def y(self, value):
        low, high = self.ylim
        value = np.asarray(value, dtype=float)
        if self.log:
            value, low, high = np.log10(np.maximum(value, 1e-300)), math.log10(low), math.log10(high)
        return self.top + self.height - (value - low) / ((high - low) or 1.0) * self.height

    def frame(self, xlabel="", ylabel="", title="", xticks=True) -> str:
        """The box, the ticks with their values and the labels."""
        out = [
            f'<rect x="{self.left:.1f}" y="{self.top:.1f}" width="{self.width:.1f}" height="{self.height:.1f}" '
            'fill="none" stroke="#000" stroke-width="0.8"/>'
        ]
        bottom = self.top + self.height
        if xticks:
            for tick in nice_ticks(*self.xlim, max(2, int(self.width // 70))):
                x = self.x(tick)
                out.append(f'<path d="M{x:.1f} {bottom:.1f}v4" stroke="#000" stroke-width="0.8"/>')
                out.append(_text(x, bottom + 15, _number(tick)))
        if self.log:
            low, high = math.ceil(math.log10(self.ylim[0]) - 1e-9), math.floor(math.log10(self.ylim[1]) + 1e-9)
            ticks = [10.0**k for k in range(low, high + 1)]
            labels = [f"1e{k}" if abs(k) > 3 else _number(10.0**k) for k in range(low, high + 1)]
        else:
            ticks = list(nice_ticks(*self.ylim, max(2, int(self.height // 60))))
            labels = [_number(t) for t in ticks]
        for tick, label in zip(ticks, labels):
            y = self.y(tick)
            out.append(f'<path d="M{self.left:.1f} {y:.1f}h-4" stroke="#000" stroke-width="0.8"/>')
            out.append(_text(self.left - 6, y + 4, label, "end"))
        if xlabel:
            out.append(_text(self.left + self.width / 2, bottom + 32, xlabel))
        if ylabel:
            width = max((len(label) for label in labels), default=1) * CHAR
            x, y = self.left - width - 16, self.top + self.height / 2
            out.append(_text(x, y, ylabel, extra=f' transform="rotate(-90 {x:.1f} {y:.1f})"'))
        if title:
            out.append(_text(self.left + self.width / 2, self.top - 8, title, extra=' font-size="13"'))
        return "".join(out)

    def vline(self, value, colour=MARK) -> str:
        x = self.x(value)
        if not self.left <= x <= self.left + self.width:
            return ""
        return (
            f'<path d="M{x:.1f} {self.top:.1f}V{self.top + self.height:.1f}" stroke="{colour}" '
            'stroke-width="1.5" stroke-dasharray="6 3"/>'
        )

    def bars(self, left_edges, widths, heights, colour) -> str:
        """Vertical bars from the bottom of the axes (one path)."""
        bottom = self.top + self.height
        d = []
        for left, width, height in zip(left_edges, widths, heights):
            if height <= 0:
                continue
            x0, x1, y = self.x(left), self.x(left + width), max(float(self.y(height)), self.top)
            d.append(f"M{x0:.2f} {bottom:.2f}V{y:.2f}H{x1:.2f}V{bottom:.2f}z")
        return f'<path d="{"".join(d)}" fill="{colour}"/>' if d else ""


def svg(width: float, height: float, body: str) -> str:
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
        f'viewBox="0 0 {width:.0f} {height:.0f}" style="max-width:100%;height:auto" {FONT}>'
        f'<rect width="100%" height="100%" fill="#fff"/>{body}</svg>'
    )


def histograms(panels, colour: str, ylabel: str, bins: int = 60) -> str:
    """Side by side, one per (values, x label, dashed mark): counts in ``bins`` bins on a log scale."""
    width, height, left, top = 330, 230, 70, 14
    body = []
    for k, (values, xlabel, mark) in enumerate(panels):
        values = np.asarray(values, dtype=float)
        values = values[np.isfinite(values)]
        counts, edges = (
            np.histogram(values, bins=bins) if len(values) else (np.zeros(bins), np.linspace(0, 1, bins + 1))
        )
        pad = 0.05 * (edges[-1] - edges[0] or 1.0)
        axes = Axes(
            left + k * (width + 80),
            top,
            width,
            height,
            (edges[0] - pad, edges[-1] + pad),
            (0.5, 2 * max(counts.max(), 1)),
            log=True,
        )
        body += [
            axes.bars(edges[:-1], np.diff(edges), counts, colour),
            axes.vline(mark),
            axes.frame(xlabel, ylabel if k == 0 else ""),
        ]
    return svg(left + len(panels) * (width + 80) - 50, top + height + 42, "".join(body))


def bar_chart(left_edges, widths, counts, colour: str, xlabel: str, ylabel: str, marks=()) -> str:
    """Bars of the given edges and widths, linear counts, dashed marks."""
    left_edges, widths, counts = (np.asarray(a, dtype=float) for a in (left_edges, widths, counts))
    low, high = (left_edges.min(), (left_edges + widths).max()) if len(left_edges) else (0.0, 1.0)
    low, high = min([low, *marks]), max([high, *marks])
    pad = 0.05 * (high - low or 1.0)
    label = max(len(_number(t)) for t in nice_ticks(0, 1.05 * max(counts.max(initial=0), 1), 5))
    axes = Axes(30 + label * CHAR, 14, 560, 240, (low - pad, high + pad), (0, 1.05 * max(counts.max(initial=0), 1)))
    body = axes.bars(left_edges, widths, counts, colour) + "".join(axes.vline(m) for m in marks)
    return svg(axes.left + 580, 14 + 240 + 42, body + axes.frame(xlabel, ylabel))


def horizontal_bars(names, values, colour: str, xlabel: str) -> str:
    """One bar per name, top to bottom."""
    values = np.asarray(values, dtype=float)
    left = 16 + max((len(n) for n in names), default=1) * CHAR
    row = 20
    axes = Axes(left, 8, 560, row * max(len(names), 1), (0, 1.05 * max(values.max(initial=0), 1e-9)), (0, 1))
    body = []
    for k, (name, value) in enumerate(zip(names, values)):
        y = axes.top + k * row
        body.append(
            f'<rect x="{axes.left:.1f}" y="{y + 3:.1f}" width="{float(axes.x(value)) - axes.left:.2f}" '
            f'height="{row - 6}" fill="{colour}"/>'
        )
        body.append(_text(axes.left - 6, y + row / 2 + 4, name, "end"))
    bottom = axes.top + axes.height
    ticks = []
    for tick in nice_ticks(*axes.xlim, 8):
        x = float(axes.x(tick))
        ticks.append(
            f'<path d="M{x:.1f} {bottom:.1f}v4" stroke="#000" stroke-width="0.8"/>'
            + _text(x, bottom + 15, _number(tick))
        )
    frame = (
        f'<rect x="{axes.left:.1f}" y="{axes.top:.1f}" width="{axes.width:.1f}" height="{axes.height:.1f}" '
        'fill="none" stroke="#000" stroke-width="0.8"/>'
    )
    body += [frame, *ticks, _text(axes.left + axes.width / 2, bottom + 32, xlabel)]
    return svg(axes.left + 580, bottom + 42, "".join(body))


def png(rgb: np.ndarray) -> bytes:
    """A PNG file of an (h, w, 3) uint8 image (each row filtered by the one above)."""
    h, w, _ = rgb.shape
    rows = rgb.reshape(h, w * 3)
    up = np.vstack([rows[:1], rows[1:] - rows[:-1]])  # uint8 wraps: PNG's 'Up' filter
    kinds = np.full((h, 1), 2, dtype=np.uint8)
    kinds[0] = 0
    raw = np.hstack([kinds, up]).tobytes()

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def rasterise(polygons: np.ndarray, width: int, height: int, xlim, ylim) -> np.ndarray:
    """(height, width) index of the polygon under each pixel centre, -1 where none; ``polygons`` (k, 4, 2) convex,
    in data coordinates (a triangle repeats its last corner), y up. Scanlines: each polygon's span on each pixel
    row it covers."""
    x = (polygons[..., 0] - xlim[0]) / (xlim[1] - xlim[0]) * width  # (k, 4) in pixels, y down
    y = (ylim[1] - polygons[..., 1]) / (ylim[1] - ylim[0]) * height
    first = np.clip(np.ceil(y.min(axis=1) - 0.5), 0, height).astype(np.int64)  # rows whose centre it covers
    last = np.clip(np.floor(y.max(axis=1) - 0.5), -1, height - 1).astype(np.int64)
    rows = np.maximum(last - first + 1, 0)
    which = np.repeat(np.arange(len(polygons)), rows)
    row = first[which] + np.arange(len(which)) - np.repeat(np.cumsum(rows) - rows, rows)
    centre = row + 0.5
    x0, y0 = x[which], y[which]  # (r, 4): edge i from corner i to corner i + 1
    x1, y1 = np.roll(x0, -1, axis=1), np.roll(y0, -1, axis=1)
    low, high = np.minimum(y0, y1), np.maximum(y0, y1)
    crosses = (low <= centre[:, None]) & (centre[:, None] <= high) & (high > low)
    at = x0 + (centre[:, None] - y0) * (x1 - x0) / np.where(high > low, y1 - y0, 1.0)
    left = np.clip(np.ceil(np.where(crosses, at, np.inf).min(axis=1) - 0.5), 0, width).astype(np.int64)
    right = np.clip(np.floor(np.where(crosses, at, -np.inf).max(axis=1) - 0.5), -1, width - 1).astype(np.int64)
    count = np.maximum(right - left + 1, 0)
    span = np.repeat(np.arange(len(which)), count)
    column = left[span] + np.arange(len(span)) - np.repeat(np.cumsum(count) - count, count)
    ids = np.full((height, width), -1, dtype=np.int64)
    ids[row[span], column] = which[span]
    return ids


def shade(ids: np.ndarray, colours: np.ndarray, border: np.ndarray, scale: int = 2, edge: float = 0.6) -> np.ndarray:
    """The (h, w, 3) image of polygon ``ids`` (at ``scale`` x the image's resolution) coloured by ``colours``
    (k, 3) uint8, white where none, the ``border`` pixels (``borders(ids)``) darkened to ``edge``, averaged down
    by ``scale``."""
    image = np.vstack([colours, [[255, 255, 255]]]).astype(np.uint8)[ids]  # id -1: the last row, white
    image[border] = (image[border] * edge).astype(np.uint8)
    h, w = ids.shape[0] // scale, ids.shape[1] // scale
    total = sum(
        image[i : h * scale : scale, j : w * scale : scale].astype(np.uint16)
        for i in range(scale)
        for j in range(scale)
    )
    return ((total + scale * scale // 2) // (scale * scale)).astype(np.uint8)


def borders(ids: np.ndarray) -> np.ndarray:
    """The pixels of a polygon whose right or lower neighbour is another polygon or none: the element edges."""
    border = np.zeros(ids.shape, dtype=bool)
    border[:, :-1] |= ids[:, :-1] != ids[:, 1:]
    border[:-1, :] |= ids[:-1, :] != ids[1:, :]
    return border & (ids >= 0)


def colour_bar(left: float, top: float, height: float, name: str, low: float, high: float) -> str:
    """A vertical colour bar of ``name`` for [low, high], its values on the right."""
    stops = "".join(f'<stop offset="{k / 16:.4f}" stop-color="#{c}"/>' for k, c in enumerate(COLOURMAPS[name].split()))
    gradient = f"bar-{name}-{left:.0f}-{top:.0f}"
    out = [
        f'<defs><linearGradient id="{gradient}" x1="0" y1="1" x2="0" y2="0">{stops}</linearGradient></defs>',
        f'<rect x="{left:.1f}" y="{top:.1f}" width="12" height="{height:.1f}" fill="url(#{gradient})" '
        'stroke="#000" stroke-width="0.8"/>',
    ]
    axis = Axes(left, top, 12, height, (0, 1), (low, high) if high > low else (low - 0.5, low + 0.5))
    for tick in nice_ticks(*axis.ylim, 5):
        y = float(axis.y(tick))
        out.append(f'<path d="M{left + 12:.1f} {y:.1f}h3" stroke="#000" stroke-width="0.8"/>')
        out.append(_text(left + 18, y + 4, _number(tick), "start"))
    return "".join(out)


def cut_panels(polygons, xlim, ylim, labels, panels, cross) -> str:
    """Panels side by side of one cut, each polygon coloured: ``panels`` a list of (title, colours (k, 3) uint8,
    legend [(colour, name)] or None, colour bar (map, low, high) or None); axes to scale with the data limits
    ``xlim``, ``ylim``, labelled ``labels``; ``cross`` the (x, y) marked with a red cross."""
    extent = (xlim[1] - xlim[0], ylim[1] - ylim[0])
    box = (330, 330 * min(max(extent[1] / extent[0], 0.3), 1.5))  # the largest panel
    scale = min(box[0] / extent[0], box[1] / extent[1])  # to scale
    w, h = max(int(round(extent[0] * scale)), 1), max(int(round(extent[1] * scale)), 1)
    ids = rasterise(polygons, 2 * w, 2 * h, xlim, ylim)
    border = borders(ids)
    top, step, body = 24, w + 150, []
    legend_rows = 0
    for k, (title, colours, legend, bar) in enumerate(panels):
        axes = Axes(70 + k * step, top, w, h, xlim, ylim)
        image = base64.b64encode(png(shade(ids, np.asarray(colours, dtype=np.uint8), border))).decode("ascii")
        body.append(
            f'<image x="{axes.left:.1f}" y="{axes.top:.1f}" width="{w}" height="{h}" '
            f'preserveAspectRatio="none" href="data:image/png;base64,{image}"/>'
        )
        x, y = float(axes.x(cross[0])), float(axes.y(cross[1]))
        body.append(f'<path d="M{x - 7:.1f} {y:.1f}h14M{x:.1f} {y - 7:.1f}v14" stroke="{MARK}" stroke-width="2"/>')
        body.append(axes.frame(labels[0], labels[1], title))
        if bar:
            body.append(colour_bar(axes.left + w + 8, axes.top, h, *bar))
        if legend:  # entries left to right, wrapped at the panel's width and its colour bar's
            x, rows = axes.left, 1
            for colour, name in legend:
                span = 14 + len(name) * CHAR + 16
                if x > axes.left and x + span > axes.left + w + 110:
                    x, rows = axes.left, rows + 1
                y = axes.top + h + 32 + 16 * rows
                body.append(f'<rect x="{x:.1f}" y="{y - 9:.1f}" width="10" height="10" fill="{colour}"/>')
                body.append(_text(x + 14, y, name, "start"))
                x += span
            legend_rows = max(legend_rows, rows)
    return svg(70 + len(panels) * step - 40, top + h + 42 + 16 * legend_rows + 12, "".join(body))
