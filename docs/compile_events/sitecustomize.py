"""Every Python process's numba compilations, logged: for `docs/kernel_compile_probe.py --logs`.

    TRUNKSLAM_COMPILE_LOG=DIR PYTHONPATH=docs/compile_events trunkslam bench cold --commands check

With `TRUNKSLAM_COMPILE_LOG` set, each process that imports numba (the warm-up's parts, each test
worker, each command a test starts) appends one JSON line per compilation to
DIR/<xdist worker or "main">-<pid>.jsonl: kernel, signature, CPU seconds (inclusive and
exclusive of the compilations nested in it) and nesting depth; the file's first line is the
process's command line and numba cache folder. numba is not imported here: the listener is
registered once numba's own import has run. Without the variable this file does nothing.
"""

import importlib.abc
import importlib.util
import json
import os
import sys
import time

_DIR = os.environ.get("TRUNKSLAM_COMPILE_LOG")


def _emit(record: dict) -> None:
    tag = os.environ.get("PYTEST_XDIST_WORKER", "main")
    path = os.path.join(_DIR, f"{tag}-{os.getpid()}.jsonl")
    new = not os.path.exists(path)
    os.makedirs(_DIR, exist_ok=True)
    with open(path, "a") as fh:
        if new:
            head = {"argv": " ".join(sys.argv)[-120:], "cache": os.environ.get("NUMBA_CACHE_DIR")}
            fh.write(json.dumps(head) + "\n")
        fh.write(json.dumps(record) + "\n")


def _install() -> None:
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
            fn = getattr((ev.data or {}).get("dispatcher"), "py_func", None)
            name = f"{fn.__module__}.{fn.__qualname__}" if fn else "?"
            args = str((ev.data or {}).get("args"))
            _emit({"kernel": name, "args": args, "cpu": cpu, "excl": cpu - nested,
                   "depth": len(stack)})  # fmt: skip

    event.register("numba:compile", Listener())


class _AfterNumba(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name != "numba":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec("numba")
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)
            _install()

        spec.loader.exec_module = exec_module
        return spec


if _DIR:
    sys.meta_path.insert(0, _AfterNumba())
