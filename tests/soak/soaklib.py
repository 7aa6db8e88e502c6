"""What the soak scripts share: their command line, the ROS domain they hold, the
record of an outage trial, the p50 and maximum of a measurement, the JSON record
they write, and their exit status (1 when a trial failed).

Imported by every soak script (this folder is on sys.path when one of them runs); it
puts tests/ on sys.path for twohost, conftest and the harnesses.
"""
import argparse
import contextlib
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import twohost  # noqa: E402
from conftest import DomainLease  # noqa: E402


def arguments(doc, **defaults):
    """The command line: the script's docstring's first paragraph as its description,
    `--NAME VALUE` for each of `defaults` (of the default's type), then `--json FILE`."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    for name, default in defaults.items():
        ap.add_argument(f"--{name}", type=type(default), default=default)
    ap.add_argument("--json", type=Path)
    return ap.parse_args()


def need_two_hosts(what="run"):
    """Exit saying why if the `pc`/`pi` namespaces cannot be made here."""
    if twohost.available():
        sys.exit(f"cannot {what}: {twohost.available()}")


@contextlib.contextmanager
def domain():
    """A ROS_DOMAIN_ID no other test on this machine holds, for the `with` block."""
    lease = DomainLease()
    try:
        yield lease.id
    finally:
        lease.release()


def outage(graph, results, trial, length, side, **extra):
    """One trial: `graph.outage(length, side)`'s record with the trial's number and
    `extra`, added to `results` and returned."""
    r = graph.outage(length, side)
    r["trial"] = trial
    r.update(extra)
    results.append(r)
    return r


def p50_max(name, values):
    """`{name}_p50_s` and `{name}_max_s`: the median and the largest of the values
    that are not None (None if none is)."""
    vs = sorted(v for v in values if v is not None)
    return {f"{name}_p50_s": statistics.median(vs) if vs else None, f"{name}_max_s": vs[-1] if vs else None}


def write_json(path, summary, date_format="%Y-%m-%d", **rest):
    """If `path`: the run as JSON there: today's date, the summary, then `rest`."""
    if path:
        path.write_text(json.dumps({"date": time.strftime(date_format), "summary": summary, **rest}, indent=1))


def failures(results, why, name="trial"):
    """["trial N (...): reason"] for each result (a dict) whose `why(result)` gives a
    reason (a falsy value: it passed); N counts from 1 as the scripts print them, the
    parenthesis has the result's length_s and side when it has them."""
    out = []
    for i, r in enumerate(results):
        reason = why(r)
        if reason:
            where = ", ".join(f"{r[k]:g} s" if k == "length_s" else str(r[k]) for k in ("length_s", "side") if k in r)
            out.append(f"{name} {r.get('trial', i) + 1}{f' ({where})' if where else ''}: {reason}")
    return out


def finish(failed, total, what="trials"):
    """End the soak: exit status 0 when `failed` (a line per failed trial, and any other
    failure, e.g. a node's exit status) is empty, else print them and exit 1, so that
    whoever runs the soak (a script, CI) sees the failure without reading its output."""
    if not failed:
        print(f"soak passed: {total} {what}, none failed", flush=True)
        sys.exit(0)
    print(f"soak FAILED: {len(failed)} failure(s) in {total} {what}:", flush=True)
    for line in failed:
        print(f"  {line}", flush=True)
    sys.exit(1)
