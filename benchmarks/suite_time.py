"""Where the test suite's time goes: the README's test command, timed whole, with each test's
wall time and JAX's tracing, lowering, compiling and cache loads in it (``_suite_probe.py``).

    python benchmarks/suite_time.py                  # the README's command, once
    python benchmarks/suite_time.py --repeat 3 --no-probe   # plain wall times only
    python benchmarks/suite_time.py -- tests/test_sweep.py  # a part (pytest's own arguments)

Run it on idle cores: the suite uses every core (``-n auto``). Prints the run's seconds, the
JAX share of the tests' time and matplotlib's drawing, the costliest tests, programs and files,
and the shared fixtures' setups; writes
benchmarks/results/suite_time.json (machine, date, every figure).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

COMMAND = "python -m pytest -q -n auto --dist worksteal"
"""The README's test command (without its install), which ``.ci/run`` runs."""
KINDS = ("trace", "lower", "compile", "load")


def run_once(extra: list[str], probe: bool) -> dict:
    """The command in a fresh process from the repository's root; with ``probe``, the
    per-test records of every process, summed."""
    cmd = [sys.executable, *shlex.split(COMMAND)[1:], *extra]
    env = dict(os.environ)
    with tempfile.TemporaryDirectory(prefix="suite-probe-") as out:
        if probe:
            cmd += ["-p", "_suite_probe"]
            env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(HERE), env.get("PYTHONPATH")]))
            env["SUITE_PROBE_DIR"] = out
        t0 = time.perf_counter()
        done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
        seconds = time.perf_counter() - t0
        tail = done.stdout.strip().splitlines()[-1:] or [""]
        result = {"seconds": seconds, "returncode": done.returncode, "summary": tail[0]}
        if probe:
            records = {p.stem: json.loads(p.read_text()) for p in Path(out).glob("*.json")}
            result.update(summarize(records))
    if done.returncode != 0:
        print(done.stdout[-3000:], done.stderr[-2000:], sep="\n", file=sys.stderr)
    return result


def summarize(records: dict[str, list]) -> dict:
    """Per test, per program name and per file: the wall time and JAX's part of it; per shared
    fixture, its setups and their time."""
    tests: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    programs: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    fixtures: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    workers = {}
    for worker, rows in records.items():
        for test, kind, name, seconds, hit in rows:
            if kind == "fixture":  # within its test's wall time, not added to it
                fixtures[name]["seconds"] += seconds
                fixtures[name]["setups"] += 1
                continue
            kind = "load" if hit else kind
            if name.startswith("jit(") and name.endswith(")"):  # lowered as jit(NAME)
                name = name[4:-1]
            tests[test or "(between tests)"][kind] += seconds
            if kind in ("compile", "load"):
                tests[test or "(between tests)"][f"{kind}s"] += 1
                programs[name][kind] += seconds
                programs[name][f"{kind}s"] += 1
            elif kind in ("trace", "lower"):
                programs[name][kind] += seconds
        workers[worker] = sum(s for _, kind, _, s, _ in rows if kind == "wall")
    totals = collections.Counter()
    for counts in tests.values():
        totals.update(counts)
    files: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for test, counts in tests.items():
        files[test.split("::")[0]].update(counts)
    by_wall = sorted(tests, key=lambda t: -tests[t]["wall"])
    by_cost = sorted(programs, key=lambda n: -sum(programs[n][k] for k in KINDS))
    return {
        "workers_test_seconds": workers,
        "tests": len([t for t in tests if tests[t]["wall"]]),
        "totals": dict(totals),
        "slowest_tests": [{"test": t, **tests[t]} for t in by_wall[:60]],
        "programs": [{"name": n, **programs[n]} for n in by_cost[:40]],
        "files": [
            {"file": f, **files[f]} for f in sorted(files, key=lambda f: -files[f]["wall"])[:30]
        ],
        "fixtures": [
            {"fixture": f, **fixtures[f]}
            for f in sorted(fixtures, key=lambda f: -fixtures[f]["seconds"])[:30]
        ],
    }


def report(run: dict, top: int) -> None:
    print(f"{run['seconds']:.1f} s: {run['summary']}")
    if "totals" not in run:
        return
    t = run["totals"]
    workers = sorted(run["workers_test_seconds"].items())
    busy = ", ".join(f"{w} {s:.0f} s" for w, s in workers if s)
    print(f"tests' own time per process: {busy}")
    jax_s = sum(t.get(k, 0.0) for k in KINDS)
    print(
        f"JAX: tracing {t.get('trace', 0):.0f} s, lowering {t.get('lower', 0):.0f} s, compiling "
        f"{t.get('compile', 0):.0f} s ({t.get('compiles', 0):,} programs), loading "
        f"{t.get('load', 0):.0f} s ({t.get('loads', 0):,} from the cache): {jax_s:.0f} of the "
        f"tests' {t.get('wall', 0):.0f} s ({jax_s / max(t.get('wall', 1), 1e-9):.0%})"
    )
    print(f"matplotlib's drawing: {t.get('draw', 0):.0f} s")
    head = f"{'wall s':>7} {'trace':>6} {'lower':>6} {'comp.':>6} {'load':>6} {'progs':>5}"
    print(f"\n{head}  slowest tests")
    for row in run["slowest_tests"][:top]:
        cells = " ".join(f"{row.get(k, 0):6.1f}" for k in KINDS)
        print(f"{row['wall']:7.1f} {cells} {row.get('compiles', 0):5d}  {row['test']}")
    print(
        f"\n{'total s':>7} {'trace':>6} {'lower':>6} {'comp.':>6} {'load':>6} {'progs':>5}  program"
    )
    for row in run["programs"][:top]:
        total = sum(row.get(k, 0.0) for k in KINDS)
        cells = " ".join(f"{row.get(k, 0):6.1f}" for k in KINDS)
        print(f"{total:7.1f} {cells} {row.get('compiles', 0):5d}  {row['name']}")
    print(f"\n{'wall s':>7} {'JAX s':>6}  file")
    for row in run["files"][:top]:
        print(f"{row['wall']:7.1f} {sum(row.get(k, 0.0) for k in KINDS):6.1f}  {row['file']}")
    print(f"\n{'setup s':>7} {'setups':>6}  shared fixture (one setup per process that uses it)")
    for row in run.get("fixtures", [])[:top]:
        print(f"{row['seconds']:7.1f} {row['setups']:6d}  {row['fixture']}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=1, help="runs of the command (1)")
    parser.add_argument("--no-probe", action="store_true", help="wall times only, no records")
    parser.add_argument("--top", type=int, default=20, help="rows per table (20)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "suite_time.json")
    parser.add_argument("pytest_args", nargs="*", help="after --: pytest's own arguments")
    args = parser.parse_args()
    if COMMAND not in (ROOT / "README.md").read_text():
        print(f"the README no longer runs {COMMAND!r}: update COMMAND", file=sys.stderr)
        return 2
    runs = []
    for i in range(args.repeat):
        runs.append(run_once(args.pytest_args, probe=not args.no_probe))
        print(f"run {i + 1} of {args.repeat}: ", end="")
        report(runs[-1], args.top)
    command = " ".join([COMMAND, *args.pytest_args])
    doc = {"machine": machine(), "command": command, "cpus": os.cpu_count(), "runs": runs}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {args.out}")
    return 0 if all(r["returncode"] == 0 for r in runs) else 1


if __name__ == "__main__":
    raise SystemExit(main())
