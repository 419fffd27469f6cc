"""What the runner shows while it works: rich bars on a terminal, plain lines otherwise.

Two bars on a TTY: steps done of the run, and the current step's own loop (from its ``@progress``
lines). Without a TTY (CI, pipes, --json) one line per step and a progress line every 10 %.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


class PlainDisplay:
    def __init__(self, out: TextIO):
        self.out = out
        self._last_pct = -1
        self._t = 0.0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def start_run(self, total: int) -> None:
        pass

    def start_step(self, name: str, index: int, total: int, note: str = "") -> None:
        self._last_pct = -1
        self._t = time.monotonic()
        self.line(f"[{index}/{total}] {name}: running{note}")

    def step_progress(self, name: str, done: int, total: int, what: str) -> None:
        pct = int(100 * done / total) if total > 0 else 0
        if pct // 10 > self._last_pct // 10 or (done >= total and self._last_pct < 100):
            self._last_pct = pct
            self.line(f"    {name}: {done}/{total} {what} ({pct}%)")

    def end_step(self, name: str, index: int, total: int, how: str, seconds: float, note: str = "") -> None:
        timing = f" in {seconds:.1f} s" if how == "ran" else ""
        self.line(f"[{index}/{total}] {name}: {how}{timing}{note}")

    def line(self, text: str) -> None:
        self.out.write(text + "\n")
        self.out.flush()


class RichDisplay(PlainDisplay):
    """Rich progress: a bar for the run's steps, one for the running step's loop."""

    def __init__(self, out: TextIO):
        super().__init__(out)
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.console = Console(file=out)
        self.progress = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=self.console,
            auto_refresh=False,
            transient=True,
        )
        self.steps = None
        self.loop = None

    def __enter__(self):
        self.progress.start()
        return self

    def __exit__(self, *exc):
        self.progress.stop()
        return False

    def start_run(self, total: int) -> None:
        self.steps = self.progress.add_task("steps", total=total)
        self.progress.refresh()

    def start_step(self, name: str, index: int, total: int, note: str = "") -> None:
        if self.loop is not None:
            self.progress.remove_task(self.loop)
        self.loop = self.progress.add_task(f"  {name}", total=None)
        self.progress.refresh()

    def step_progress(self, name: str, done: int, total: int, what: str) -> None:
        if self.loop is not None:
            self.progress.update(self.loop, completed=done, total=total, description=f"  {name} {what}")
            self.progress.refresh()

    def end_step(self, name: str, index: int, total: int, how: str, seconds: float, note: str = "") -> None:
        if self.loop is not None:
            self.progress.remove_task(self.loop)
            self.loop = None
        if self.steps is not None:
            self.progress.update(self.steps, completed=index)
        timing = f" in {seconds:.1f} s" if how == "ran" else ""
        colour = {"ran": "green", "cached": "dim", "cut off": "cyan", "used": "magenta"}.get(how, "")
        self.console.print(
            f"[{index}/{total}] {name}: [{colour}]{how}[/]{timing}{note}"
            if colour
            else f"[{index}/{total}] {name}: {how}{timing}{note}",
            highlight=False,
        )
        self.progress.refresh()

    def line(self, text: str) -> None:
        self.console.print(text, highlight=False, markup=False)
        self.progress.refresh()


def make_display(out: TextIO = sys.stdout, fancy: bool | None = None) -> PlainDisplay:
    if fancy is None:
        fancy = out.isatty()
    return RichDisplay(out) if fancy else PlainDisplay(out)
