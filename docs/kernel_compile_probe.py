"""Probe behind issue 45's cold `make check`: where a cold warm-up's CPU goes, kernel by kernel.

    PYTHONPATH=. .venv/bin/python docs/kernel_compile_probe.py [--top 12]
    PYTHONPATH=. .venv/bin/python docs/kernel_compile_probe.py --logs DIR

`--logs DIR`: the compilations of every process of a command run with
`docs/compile_events/sitecustomize.py` (see there; e.g. a cold `make check` through `trunkslam
bench cold`), per process: its top-level compilation seconds, and our kernels it compiled.

Runs each part of the warm-up (`experiments.bench.warm.PARTS`), one after the other, each in a
process of its own with an empty numba cache folder (a fresh clone's), and listens to numba's
"numba:compile" events (`numba.core.event`; one per compilation, none for a kernel loaded from
the cache), timing each in CPU seconds of that process. Prints, per part: the process's CPU
seconds, the seconds of its top-level compilations, those seconds by class (our packages, and
numba's own library code compiled into them: array creation, sorting, error messages), the
kernels compiled more than once (a second signature), and the costliest kernels with their
callees (inclusive) and alone (exclusive). A callee compiled inside its caller counts in the
caller's inclusive time; numba compiles a library function once per process, inside the first
kernel that needs it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path


def _listen(records: list[dict]) -> None:
    """Record every compilation of this process: kernel, signature, CPU s (inclusive and
    exclusive of the compilations nested in it) and nesting depth."""
    from numba.core import event

    stack: list[list[float]] = []

    class Listener(event.Listener):
        def on_start(self, ev):
            stack.append([time.process_time(), 0.0])

        def on_end(self, ev):
            t0, nested = stack.pop()
            cpu = time.process_time() - t0
            if stack:
                stack[-1][1] += cpu
            fn = getattr(ev.data.get("dispatcher"), "py_func", None)
            name = f"{fn.__module__}.{fn.__qualname__}" if fn else "?"
            records.append(
                {
                    "kernel": name,
                    "args": str(ev.data.get("args")),
                    "cpu": cpu,
                    "excl": cpu - nested,
                    "depth": len(stack),
                }
            )

    event.register("numba:compile", Listener())


def _run_part(name: str, out: Path) -> None:
    t0 = time.process_time()
    import numba  # noqa: F401

    from experiments.bench.warm import PARTS

    records: list[dict] = []
    _listen(records)
    t_import = time.process_time() - t0
    PARTS[name]()
    out.write_text(
        json.dumps({"cpu_s": time.process_time(), "import_s": t_import, "records": records})
    )


def _class(kernel: str) -> str:
    top = kernel.split(".")[0]
    return top if top in ("features", "association", "slam", "experiments") else "numba library"


def _report(name: str, data: dict, top: int) -> None:
    recs = data["records"]
    compile_s = sum(r["cpu"] for r in recs if r["depth"] == 0)
    print(
        f"\n## part {name}: process {data['cpu_s']:.1f} s CPU (imports {data['import_s']:.1f}), "
        f"compilations {compile_s:.1f} s ({len(recs)} compilations)"
    )
    by_class: dict[str, float] = defaultdict(float)
    for r in recs:
        by_class[_class(r["kernel"])] += r["excl"]
    print(
        "  by class (exclusive s): "
        + ", ".join(f"{k} {v:.1f}" for k, v in sorted(by_class.items()))
    )
    sigs: dict[str, set] = defaultdict(set)
    incl: dict[str, float] = defaultdict(float)
    excl: dict[str, float] = defaultdict(float)
    for r in recs:
        sigs[r["kernel"]].add(r["args"])
        incl[r["kernel"]] += r["cpu"]
        excl[r["kernel"]] += r["excl"]
    multi = [k for k, s in sigs.items() if len(s) > 1 and _class(k) != "numba library"]
    print(f"  our kernels with more than one signature: {multi or 'none'}")
    errors = sum(incl[k] for k in incl if "raise_with_shape_context" in k)
    print(f"  numba's slice-assignment error message: {errors:.1f} s")
    print(f"  {'kernel':<52} {'incl s':>7} {'excl s':>7}")
    for k in sorted(incl, key=lambda k: -incl[k])[:top]:
        print(f"  {k[-52:]:<52} {incl[k]:7.2f} {excl[k]:7.2f}")


def _report_logs(folder: Path) -> None:
    """Per process of a `docs/compile_events` log folder: top-level compile CPU s, and ours."""
    total = 0.0
    for path in sorted(folder.glob("*.jsonl")):
        lines = [json.loads(line) for line in path.read_text().splitlines()]
        head, recs = lines[0], lines[1:]
        top = [r for r in recs if r["depth"] == 0]
        seconds = sum(r["cpu"] for r in top)
        total += seconds
        print(f"\n{path.stem} ({head['argv'][-50:]}): {seconds:.1f} s, {len(recs)} compilations")
        for r in top:
            if _class(r["kernel"]) != "numba library":
                print(f"  {r['cpu']:6.2f}  {r['kernel']} {r['args'][:90]}")
    print(f"\nall processes: {total:.1f} s of compilation")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--top", type=int, default=12, help="kernels listed per part")
    parser.add_argument("--logs", type=Path, help="summarise a docs/compile_events log folder")
    parser.add_argument("--part", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.part:
        _run_part(args.part, args.out)
        return
    if args.logs:
        _report_logs(args.logs)
        return
    from experiments.bench.warm import PARTS

    print(f"load average before: {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory(prefix="compile-probe-") as tmp:
        for name in PARTS:
            out = Path(tmp) / f"{name}.json"
            env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(tmp) / f"cache-{name}")}
            env["OMP_NUM_THREADS"] = "1"
            cmd = [sys.executable, __file__, "--part", name, "--out", str(out)]
            subprocess.run(cmd, env=env, check=True, timeout=3600)
            _report(name, json.loads(out.read_text()), args.top)
    print(f"\nload average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
