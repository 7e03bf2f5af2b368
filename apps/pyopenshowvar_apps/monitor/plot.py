"""The monitor's history plots: sparklines whose scale never magnifies sensor noise.

Textual's own :class:`~textual.widgets.Sparkline` stretches whatever the data spans over its
full height, so a robot standing still drew its encoder noise (10⁻⁴°) and its torque noise as
wild swings. :class:`Plot` gives every level of the plot a minimum height, the larger of

* ``resolution``, the precision the panels print (a smaller change is not shown anywhere), and
* ``NOISE_STEPS`` times the sensor noise, estimated from the history itself (:func:`noise`):
  the plot does not draw what the sensor cannot tell from noise.

While the history spans less than the plot's levels × that height, each level is one step and
the median of the history sits in the middle of a level, so noise around a value at rest is
drawn as a flat line; a larger span is drawn over the full height, as before. Each column shows
the mean of the samples that fall into it.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterator, Sequence

from rich.color import Color
from rich.console import Console, ConsoleOptions, RenderResult
from rich.segment import Segment
from rich.style import Style
from textual.app import RenderResult as TextualRenderResult
from textual.renderables._blend_colors import blend_colors
from textual.widgets import Sparkline

__all__ = ["BARS", "NOISE_STEPS", "Plot", "levels_of", "noise"]

#: One line of a plot has eight levels.
BARS = "▁▂▃▄▅▆▇█"
#: A level is at least this many standard deviations of the noise tall: the noise (±6 σ) stays
#: within the level the median sits in.
NOISE_STEPS = 12


def noise(data: Sequence[float]) -> float:
    """The standard deviation of the samples' noise: robust, and blind to smooth motion.

    Second differences remove a motion's steady part (a constant speed gives 0), and their
    median absolute value ignores the few a change of speed disturbs; white noise of σ gives
    second differences of √6·σ, whose median absolute value is 0.6745 times that.
    """
    if len(data) < 5:
        return 0.0
    second = [abs(data[i + 1] - 2.0 * data[i] + data[i - 1]) for i in range(1, len(data) - 1)]
    return statistics.median(second) / (0.6745 * math.sqrt(6.0))


def _columns(data: Sequence[float], width: int) -> list[float]:
    """The mean of the samples of each of ``width`` columns (fewer samples: repeated)."""
    n = len(data)
    out = []
    for c in range(width):
        start = c * n // width
        end = max((c + 1) * n // width, start + 1)
        out.append(statistics.fmean(data[start:end]))
    return out


def levels_of(values: Sequence[float], resolution: float, levels: int) -> list[int]:
    """The level (0 … ``levels`` - 1) each value is drawn at; see the module docstring."""
    if not values:
        return []
    low, high = min(values), max(values)
    step = (high - low) / levels
    if step <= resolution:
        step = resolution
        # the median in the middle of the middle level, then shifted so every value fits
        low = statistics.median(values) - ((levels - 1) // 2 + 0.5) * step
        low = max(min(low, min(values)), max(values) - levels * step)
    top = levels - 1
    return [min(top, max(0, math.floor((v - low) / step))) for v in values]


class _Bars:
    """The Rich renderable of a :class:`Plot`: one column per data bucket."""

    def __init__(
        self, data: Sequence[float], resolution: float, height: int, colors: tuple[Color, Color]
    ) -> None:
        self.data, self.resolution, self.height, self.colors = data, resolution, height, colors

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        width, height = options.max_width, max(1, self.height)
        columns = _columns(self.data, width) if self.data else [0.0] * width
        total = 8 * height
        step = max(self.resolution, NOISE_STEPS * noise(self.data))
        levels = levels_of(columns, step, total)
        shades = {
            lv: Style.from_color(blend_colors(*self.colors, lv / (total - 1))) for lv in set(levels)
        }
        styles = [shades[lv] for lv in levels]
        for row in reversed(range(height)):
            yield from self._line(levels, styles, row)
            if row:
                yield Segment.line()

    @staticmethod
    def _line(levels: list[int], styles: list[Style], row: int) -> Iterator[Segment]:
        for level, style in zip(levels, styles, strict=True):
            if level < 8 * row:
                yield Segment(" ")
            else:
                yield Segment(BARS[min(7, level - 8 * row)], style)


class Plot(Sparkline):
    """A :class:`~textual.widgets.Sparkline` that draws noise and changes below ``resolution``
    flat (see the module)."""

    def __init__(self, *, resolution: float, id: str | None = None) -> None:
        super().__init__([], id=id)
        self.resolution = resolution

    def render(self) -> TextualRenderResult:
        _, base = self.background_colors
        low = base + self.get_component_styles("sparkline--min-color").color
        high = base + self.get_component_styles("sparkline--max-color").color
        colors = (low.rich_color, high.rich_color)
        return _Bars(list(self.data or []), self.resolution, self.size.height, colors)
