"""`trunkslam reproduce`: run experiments from the registry into one result set.

The result set is written atomically (`experiments.io.writers.atomic_folder`): every experiment
writes into a temporary folder beside the output folder, `manifest.json` is written last and
lists exactly the files of that folder, and only then does the folder replace the previous one
as a whole. An interruption or a write error (a full disk) leaves the previous set untouched.
An experiment that fails on bad input (corrupt data, an impossible parameter: the project's own
errors) is recorded under "failed" in the manifest, its partial files are removed, the others
still run, and the run ends with `ExperimentFailed` (exit code 1); the previous set, including
that experiment's old outputs, is replaced, so nothing stale looks current. A bug (any other
exception) or an OSError stops the run at once and leaves the previous set untouched.

Experiments hand parts of their work to the executor without waiting for it (recordings,
figures, runs whose table can wait: `RunContext.later`); those parts are finished, and their
files written, after the last experiment has started, so that their trials share the workers
with the next experiments' trials instead of leaving workers idle while this process works or
waits. An error there fails its experiment as above. The seconds in the manifest are this
process's time on each experiment: its body, and the wait for and writing of its deferred parts.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

from experiments.errors import DataError, ExperimentFailed, input_errors
from experiments.exec import Batch, Executor, SerialExecutor
from experiments.io.outputs import MANIFEST, check_output_folder, check_outputs, lock_folder
from experiments.io.paths import victoria_park_dir
from experiments.io.provenance import git_commit, machine, versions
from experiments.io.writers import atomic_folder, dumps_json, write_atomic
from experiments.paper.runner import DEFAULT_EXPERIMENTS, RunContext, get_experiment

__all__ = ["MANIFEST", "run_experiments"]

log = logging.getLogger(__name__)


def _files(folder: Path) -> set[str]:
    """Every file under folder, as paths relative to it."""
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if not p.is_dir()}


def _remove(folder: Path, names: set[str]) -> None:
    for name in names:
        (folder / name).unlink(missing_ok=True)
    for d in sorted((p for p in folder.rglob("*") if p.is_dir()), reverse=True):
        if not any(d.iterdir()):
            d.rmdir()


class _Ledger:
    """The bookkeeping of one result set while its experiments run in `stage` (the temporary
    folder): per experiment the files and configuration keys it added, its deferred parts, its
    time, and the failures. An experiment that fails loses its files, its keys and its
    deferred parts; the others go on."""

    def __init__(self, ctx: RunContext, stage: Path, failures: tuple) -> None:
        self.ctx = ctx
        self.stage = stage
        self.failures = failures  # errors that fail one experiment; any other stops the run
        self.failed: dict[str, str] = {}
        self.timings: dict[str, float] = {}
        self.owned: dict[str, tuple[set[str], set[str]]] = {}
        self.deferred: list[tuple[str, Batch, Callable]] = []
        self.commit = git_commit()  # the code the run started from, not the tree at its end

    def fail(self, name: str, exc: BaseException, files: set[str], keys: set[str]) -> None:
        log.error("experiment %s failed: %s", name, exc)
        self.failed[name] = f"{type(exc).__name__}: {exc}"
        self.timings.pop(name, None)
        _remove(self.stage, files)
        for k in keys:
            self.ctx.config.pop(k, None)
        for n, batch, _ in self.deferred:
            if n == name:
                batch.cancel()

    def run(self, fn: Callable, group: list[str]) -> bool:
        """Run one experiment (`group`: the names its function stands for); False when it
        failed on bad input."""
        ctx = self.ctx
        name = " ".join(group)
        log.info("running %s", name)
        t0, c0 = time.perf_counter(), time.process_time()
        before_files, before_config = _files(self.stage), set(ctx.config)
        n_deferred = len(ctx.deferred)
        try:
            fn(ctx)
        except self.failures as exc:
            self.deferred += [(name, b, f) for b, f in ctx.deferred[n_deferred:]]
            self.fail(name, exc, _files(self.stage) - before_files, set(ctx.config) - before_config)
            return False
        except BaseException:
            for b, _ in ctx.deferred:  # a bug or an interruption: nothing more is wanted
                b.cancel()
            raise
        self.deferred += [(name, b, f) for b, f in ctx.deferred[n_deferred:]]
        self.timings[name] = round(time.perf_counter() - t0, 2)
        # the resolved parameters, under every name the run stands for
        written = [k for k in ctx.config if k not in before_config and ctx.config[k]]
        shared = ctx.config[written[0]] if written else {}
        for n in group:  # an entry still empty may be filled by a deferred part: kept
            if n not in ctx.config or (written and not ctx.config[n]):
                ctx.config[n] = shared
        self.owned[name] = (_files(self.stage) - before_files, set(ctx.config) - before_config)
        log.info(
            "%s done in %.1f s (%.1f s CPU in this process)",
            name,
            self.timings[name],
            time.process_time() - c0,
        )
        return True

    def finish_deferred(self) -> None:
        """The parts the experiments deferred (`RunContext.later`), in the order handed over:
        their trials ran beside the later experiments' trials."""
        for k, (name, batch, finish) in enumerate(self.deferred):
            if name in self.failed:
                continue
            t0, c0 = time.perf_counter(), time.process_time()
            before_files = _files(self.stage)
            try:
                finish(batch.result(self.ctx.progress))
            except self.failures as exc:
                files, keys = self.owned[name]
                self.fail(name, exc, files | (_files(self.stage) - before_files), keys)
                continue
            except BaseException:
                for _, b, _ in self.deferred[k + 1 :]:
                    b.cancel()
                raise
            self.owned[name][0].update(_files(self.stage) - before_files)
            self.timings[name] = round(self.timings[name] + time.perf_counter() - t0, 2)
            log.info(
                "%s: deferred part (%s) done in %.1f s (%.1f s CPU in this process)",
                name,
                batch.desc,
                time.perf_counter() - t0,
                time.process_time() - c0,
            )

    def manifest(self, names: list[str], executor: Executor) -> dict:
        """manifest.json: what ran, how, with which parameters, and every file of the set."""
        ctx = self.ctx
        return {
            "command": "trunkslam reproduce",
            "experiments": names,
            "quick": ctx.quick,
            "seed": ctx.seed,
            "git_commit": self.commit,
            **_changed_during(self.commit),
            "finished": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": machine(),
            "versions": versions(),
            "config": ctx.config,
            "seconds": self.timings,
            "executor": executor.describe(),
            "failed": self.failed,
            "outputs": sorted(_files(self.stage)),
        }


def _changed_during(started: str | None) -> dict:
    """{"git_commit_at_end": ...} when the checkout changed while the run ran (a commit, or an
    edit that made it dirty), else {}: the manifest names the code a run started from and says
    when its tree moved under it."""
    now = git_commit()
    return {} if now == started else {"git_commit_at_end": now}


def run_experiments(
    names: list[str],
    out_dir: Path,
    quick: bool = False,
    seed: int = 0,
    progress: Callable[[str, int, int], None] | None = None,
    executor: Executor | None = None,
) -> list[Path]:
    """Run the named experiments (all when empty) into out_dir, replacing what was there as one
    set (see the module doc); returns the files written. out_dir must be absent, empty or an
    earlier result set every file of which its manifest.json lists; it is held
    (`experiments.io.outputs.lock_folder`) while the experiments run. The experiments' trials
    run on `executor` (`experiments.exec`; default: this process); the results do not depend
    on it. Raises
    `ExperimentFailed` after the run when an experiment failed (a trial that raised fails its
    experiment, named with its seed)."""
    executor = executor or SerialExecutor()
    names = list(dict.fromkeys(names)) or list(DEFAULT_EXPERIMENTS)
    groups: dict[Callable, list[str]] = {}  # names that share a function are one run
    for n in names:  # unknown names fail before any work
        groups.setdefault(get_experiment(n), []).append(n)
    out_dir = Path(out_dir)
    check_outputs("reproduce", inputs=[_data_folder()], folders={"--out": out_dir})
    with lock_folder(out_dir, "--out"):
        check_output_folder(out_dir, "--out", "reproduce")  # again, now that it is held
        return _run_held(
            groups, names, out_dir, (quick, seed), progress=progress, executor=executor
        )


def _data_folder() -> Path | None:
    """The Victoria Park folder the experiments read, when there is one (an input)."""
    try:
        return victoria_park_dir()
    except DataError:
        return None


def _run_held(groups: dict, names: list[str], out_dir: Path, run, *, progress, executor) -> list:
    """`run_experiments` with out_dir held; run: (quick, seed)."""
    quick, seed = run
    # errors that fail one experiment; OSError (a full disk, ...) and bugs stop the whole run
    failures = tuple(e for e in input_errors() if e is not OSError)
    with atomic_folder(out_dir) as stage:
        ctx = RunContext(out_dir=stage, quick=quick, seed=seed, executor=executor)
        if progress is not None:
            ctx.progress = progress
        ledger = _Ledger(ctx, stage, failures)
        for i, (fn, group) in enumerate(groups.items()):
            ctx.progress("experiments", i, len(groups))
            if ledger.run(fn, group):
                ctx.progress("experiments", i + 1, len(groups))
        ledger.finish_deferred()
        manifest = ledger.manifest(names, executor)
        write_atomic(stage / MANIFEST, dumps_json(manifest))  # last: the set is complete
    if ledger.failed:
        what = "; ".join(f"{k}: {v}" for k, v in ledger.failed.items())
        raise ExperimentFailed(
            f"{len(ledger.failed)} experiment(s) failed ({what}). The other results are in "
            f"{out_dir}/ ({MANIFEST} lists the failure); nothing of the earlier run was kept."
        )
    return [out_dir / p for p in manifest["outputs"]] + [out_dir / MANIFEST]
