"""Where a run's time goes: seconds per pipeline stage (``delaunay-infill process --stages``).

A stage is timed exclusively: a stage entered inside another one is taken out of the outer
stage's time, so the stages of a run add up to the time spent in them.  The clock is off unless
a run is given one (`OFF`: a shared no-op), so an ordinary run pays one method call per stage.
"""

from __future__ import annotations

import time

__all__ = ["STAGES", "StageClock", "OFF"]

# The stages in pipeline order, with what each one covers.
STAGES = {
    "parse": "reading a layer's moves into arrays (read.parse_layer)",
    "areas": "each mesh's infill area from walls and skin, confirmed by Cura's lines (area, witness)",
    "patterns": "the Delaunay pattern for the area and its regions, clipped to the area (pattern)",
    "density report": "measuring the new infill per density region (the summary's region table)",
    "Cura's lines kept": "Cura's own lines where the new infill does not take over (witness.kept_cura_pieces)",
    "routes": "sharing the paths among Cura's FILL blocks (routing)",
    "emit": "writing the new moves as G-code (emit)",
    "estimate": "print time of the new and the old moves (estimate)",
    "repeated layers": "writing a layer from the record of an earlier layer it repeats (replay)",
    "repeat records": "recording a processed layer for later repeats (replay)",
    "other": "everything else in the run: splitting, per-layer bookkeeping, the header",
}


class _Stage:
    __slots__ = ("clock", "name", "start")

    def __init__(self, clock: StageClock, name: str):
        self.clock, self.name = clock, name

    def __enter__(self):
        self.clock._inner.append(0.0)
        self.start = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        spent = time.perf_counter() - self.start
        inner = self.clock._inner.pop()
        seconds = self.clock.seconds
        seconds[self.name] = seconds.get(self.name, 0.0) + spent - inner
        if self.clock._inner:
            self.clock._inner[-1] += spent


class _NoStage:
    __slots__ = ()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        return None


_NO_STAGE = _NoStage()


class StageClock:
    """Seconds per stage over one run.

    Attributes
    ----------
    seconds : dict
        Stage name (`STAGES`) -> exclusive seconds, summed over the run.
    total : float
        Wall seconds of the whole run (set by the caller), s.
    """

    enabled = True

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self.total = 0.0
        self._inner: list[float] = []

    def __call__(self, name: str):
        return _Stage(self, name)

    def table(self, layers_processed: int) -> str:
        """A plain-text table: seconds, ms per processed layer and share of the run per stage."""
        timed = sum(self.seconds.values())
        rows = dict(self.seconds)
        rows["other"] = rows.get("other", 0.0) + max(0.0, self.total - timed)
        per = max(1, layers_processed)
        out = [f"{'stage':20s} {'seconds':>8s} {'ms/layer':>9s} {'share':>6s}  what"]
        for name in STAGES:
            if name not in rows:
                continue
            s = rows[name]
            share = s / self.total * 100 if self.total > 0 else 0.0
            out.append(f"{name:20s} {s:8.3f} {s / per * 1000:9.2f} {share:5.1f}%  {STAGES[name]}")
        out.append(f"{'total':20s} {self.total:8.3f} {self.total / per * 1000:9.2f} {100.0:5.1f}%  "
                   f"over {layers_processed} processed layers (ms/layer: per processed layer)")
        return "\n".join(out)


class _Off:
    """The clock of a run that is not timed: every stage is a shared no-op."""

    enabled = False

    def __call__(self, name: str):
        return _NO_STAGE


OFF = _Off()
