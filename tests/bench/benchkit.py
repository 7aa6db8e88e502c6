"""What the simavr benchmarks share: their statistics line and a launcher of nodes in
one ROS domain (the tests' `launch` fixture, outside pytest)."""
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from conftest import NodeProcess  # noqa: E402


def stats(xs):
    """n, p50, p99 (nearest rank) and max of `xs`, rounded to 0.01."""
    xs = sorted(xs)
    return {"n": len(xs), "p50": round(statistics.median(xs), 2),
            "p99": round(xs[min(len(xs) - 1, int(round(0.99 * (len(xs) - 1))))], 2), "max": round(xs[-1], 2)}


class Launcher:
    """`launch(name, *args)` starts a node in `domain`; `stop()` stops every one, returning
    their exit codes."""

    def __init__(self, domain):
        self.domain, self.procs = domain, []

    def __call__(self, name, *args):
        p = NodeProcess(name, list(args), self.domain)
        self.procs.append(p)
        return p

    def stop(self):
        return [p.stop() for p in self.procs]
