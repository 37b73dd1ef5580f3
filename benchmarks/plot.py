"""Tiny line plots for the benchmark page, drawn with Pillow (no plotting library needed).

``line_plot(path, series, ...)`` draws one or more (x, y) series with markers on labelled axes
with "nice" ticks, optionally a logarithmic x axis and horizontal reference lines, and writes
the PNG atomically (temporary file in the same folder, then rename).
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

#: Colours of successive series (and reference lines), colour-blind friendly (Okabe-Ito).
PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9")


@dataclass(frozen=True)
class Series:
    """One line: its label in the legend, points (x, y) and whether to draw it dashed."""

    label: str
    points: Sequence[tuple[float, float]]
    dashed: bool = False


def nice_ticks(low: float, high: float, count: int = 5) -> list[float]:
    """About ``count`` round tick values (1, 2, 2.5 or 5 times a power of ten) covering
    [low, high]."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return [0.0, 1.0]
    if high <= low:
        high = low + 1.0
    raw = (high - low) / max(count - 1, 1)
    power = 10 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1, 2, 2.5, 5, 10) if m * power >= raw)
    first = math.floor(low / step + 1e-9) * step
    ticks = []
    value = first
    while value < high + step * 0.999:
        ticks.append(round(value, 10))
        value += step
    return ticks


def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1 or no FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _label(value: float) -> str:
    return f"{value:g}"


def line_plot(
    path: Path | str,
    series: Sequence[Series],
    *,
    title: str,
    x_label: str,
    y_label: str,
    log_x: bool = False,
    categorical_x: bool = False,
    x_ticks: Sequence[float] | None = None,
    y_range: tuple[float, float] | None = None,
    size: tuple[int, int] = (800, 500),
) -> Path:
    """Draw ``series`` as lines with markers and write a PNG to ``path`` atomically.

    ``log_x`` spaces x logarithmically (values must be positive); ``categorical_x`` spaces the
    x ticks evenly whatever their values (points must lie on ticks; for doubling budgets with a
    zero point); ``x_ticks`` fixes the x tick values (default: every distinct x); ``y_range`` fixes the y axis (default: the data padded,
    rounded to ticks). Returns ``path``.
    """
    path = Path(path)
    width, height = size
    image = Image.new("RGB", size, "white")
    draw = ImageDraw.Draw(image)
    title_font, font, small = _font(20), _font(15), _font(13)
    left, right, top, bottom = 80, 30, 50, 70  # margins around the plotting area
    xs = sorted({x for s in series for x, _ in s.points})
    ys = [y for s in series for _, y in s.points if math.isfinite(y)]
    if not xs:
        raise ValueError("nothing to plot")
    x_ticks = list(x_ticks) if x_ticks is not None else xs

    order = sorted(set(x_ticks) | set(xs))

    def fx(value: float) -> float:
        if categorical_x:
            return float(order.index(value))
        return math.log10(value) if log_x else value

    x_low, x_high = fx(min(*x_ticks, *xs)), fx(max(*x_ticks, *xs))
    if x_high <= x_low:
        x_low, x_high = x_low - 1, x_high + 1
    pad = 0.05 * (x_high - x_low)
    x_low, x_high = x_low - pad, x_high + pad
    if y_range is None:
        low, high = (min(ys), max(ys)) if ys else (0.0, 1.0)
        spread = max(high - low, 0.02)
        y_ticks = nice_ticks(low - 0.1 * spread, high + 0.1 * spread)
    else:
        y_ticks = nice_ticks(*y_range)
    y_low, y_high = y_ticks[0], y_ticks[-1]
    plot_w, plot_h = width - left - right, height - top - bottom

    def px(x: float, y: float) -> tuple[float, float]:
        u = left + (fx(x) - x_low) / (x_high - x_low) * plot_w
        v = top + (1 - (y - y_low) / (y_high - y_low)) * plot_h
        return u, v

    # Title, grid, axes, ticks and labels.
    draw.text((width / 2, 14), title, fill="black", font=title_font, anchor="mt")
    for tick in y_ticks:
        _, v = px(xs[0], tick)
        draw.line([(left, v), (left + plot_w, v)], fill="#e6e6e6")
        draw.line([(left - 5, v), (left, v)], fill="black")
        draw.text((left - 8, v), _label(tick), fill="black", font=small, anchor="rm")
    for tick in x_ticks:
        u, _ = px(tick, y_low)
        draw.line([(u, top), (u, top + plot_h)], fill="#f0f0f0")
        draw.line([(u, top + plot_h), (u, top + plot_h + 5)], fill="black")
        draw.text((u, top + plot_h + 8), _label(tick), fill="black", font=small, anchor="mt")
    draw.rectangle([left, top, left + plot_w, top + plot_h], outline="black")
    draw.text((left + plot_w / 2, height - 12), x_label, fill="black", font=font, anchor="mb")
    label = Image.new("RGBA", (plot_h, 24), (255, 255, 255, 0))
    ImageDraw.Draw(label).text((plot_h / 2, 12), y_label, fill="black", font=font, anchor="mm")
    rotated = label.rotate(90, expand=True)
    image.paste(rotated, (8, top), rotated)

    # Lines with markers, and the legend (top left inside the plot).
    legend_y = top + 10
    for index, line in enumerate(series):
        colour = PALETTE[index % len(PALETTE)]
        points = [px(x, y) for x, y in sorted(line.points) if math.isfinite(y)]
        if len(points) > 1:
            if line.dashed:
                for a, b in zip(points, points[1:], strict=False):
                    _dashed(draw, a, b, colour)
            else:
                draw.line(points, fill=colour, width=3, joint="curve")
        if line.dashed:
            _dashed(draw, (left + 12, legend_y + 8), (left + 42, legend_y + 8), colour)
        else:
            for u, v in points:
                draw.ellipse([u - 5, v - 5, u + 5, v + 5], fill=colour, outline="white")
            draw.line([(left + 12, legend_y + 8), (left + 42, legend_y + 8)], fill=colour, width=3)
            draw.ellipse([left + 22, legend_y + 3, left + 32, legend_y + 13], fill=colour)
        draw.text((left + 50, legend_y + 8), line.label, fill="black", font=small, anchor="lm")
        legend_y += 22

    path.parent.mkdir(parents=True, exist_ok=True)
    handle, staging = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=".png", dir=path.parent)
    try:
        with os.fdopen(handle, "wb") as stream:
            image.save(stream, format="PNG", optimize=True)
        os.chmod(staging, 0o644)  # mkstemp creates 0600
        os.replace(staging, path)
    except BaseException:
        Path(staging).unlink(missing_ok=True)
        raise
    return path


def _dashed(
    draw: ImageDraw.ImageDraw, a: tuple[float, float], b: tuple[float, float], colour: str
) -> None:
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    dash = 8.0
    steps = max(int(length // dash), 1)
    for step in range(0, steps, 2):  # dash, gap, dash, ...
        t0, t1 = step / steps, min((step + 1) / steps, 1.0)
        draw.line(
            [
                (a[0] + (b[0] - a[0]) * t0, a[1] + (b[1] - a[1]) * t0),
                (a[0] + (b[0] - a[0]) * t1, a[1] + (b[1] - a[1]) * t1),
            ],
            fill=colour,
            width=3,
        )
