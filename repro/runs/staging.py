"""Run folders written aside and swapped in whole (issue 40).

A run never writes into the folder it makes. It writes into its *staging folder*, a
sibling on the same file system, and replaces its *target* only when the run function
returned (the run closed whole: completed, or failed by its own test)::

    results/chan2011/simulation/             the target: the complete run, untouched while
                                             a new one is made
    results/chan2011/.partial/simulation/    the staging folder: the run being made, or the
                                             partial run a signal, a crash or a kill left
    results/chan2011/.replaced/simulation/   the old run, only during a swap

The staging folder keeps the target's own name (a run's experiment name defaults to its
folder's name), one level down in a hidden folder, so that ``<results>/<paper>/*/`` (the
runs ``repro results``, figures, claims and tests look at) never holds it;
:func:`is_aside` tells code that walks folders deeper (the report) to skip it.

The swap (:func:`_swap`): rename target -> ``.replaced/<name>``, rename staging -> target,
remove ``.replaced/<name>``. Two renames of directories on one file system are cheap (no
file is copied) but not one atomic step, so a process killed between them leaves the old
run aside with no target; :func:`recover` (called before every run of a target, and by
``repro results`` for every paper) puts it back, or removes it if the new run is in place.
Swaps and recoveries under one parent folder hold an flock on that parent (held for a few
renames), so a recovery never undoes another process's swap in flight; SIGINT / SIGTERM are
held through the swap (:func:`repro.runs.signals.deferred`).

:func:`run_folder_lock` (an flock on a folder itself) guards the folder a process writes: a
run's staging folder, or a sweep's folder. Nothing written inside a run folder names the
staging path: run files name their neighbours by relative paths (the URDF copies and their
meshes, ``columns_file``), so a swapped-in folder reads as if it had been made in place.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

from repro.errors import ReproError

__all__ = ["PARTIAL_DIR", "REPLACED_DIR", "is_aside", "partial_runs", "recover",
           "recover_all", "replaced_dir", "run_folder_lock", "staged", "staging_dir"]

#: Hidden folder beside the targets holding the staging folders (a stopped run stays here).
PARTIAL_DIR = ".partial"
#: Hidden folder beside the targets holding a replaced run during a swap.
REPLACED_DIR = ".replaced"
MANIFEST_NAME = "manifest.json"


def staging_dir(target: Path) -> Path:
    """Where a run of ``target`` is written: ``<parent>/.partial/<name>``."""
    target = Path(target)
    return target.parent / PARTIAL_DIR / target.name


def replaced_dir(target: Path) -> Path:
    """Where ``target``'s old run waits during a swap: ``<parent>/.replaced/<name>``."""
    target = Path(target)
    return target.parent / REPLACED_DIR / target.name


def is_aside(path: Path) -> bool:
    """Whether ``path`` lies in a staging or replaced folder (never a run to read)."""
    return any(part in (PARTIAL_DIR, REPLACED_DIR) for part in Path(path).parts)


def partial_runs(parent: Path) -> list[Path]:
    """The staging folders under ``parent`` (``parent/.partial/*/``), sorted."""
    folder = Path(parent) / PARTIAL_DIR
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_dir())


@contextlib.contextmanager
def run_folder_lock(out_dir: Path) -> Iterator[None]:
    """Hold an exclusive lock on the folder ``out_dir`` (``flock`` on the folder itself: no
    lock file, released by the kernel when the process dies) while this process writes it:
    a run's staging folder, a sweep's folder. Creates the folder.

    Raises:
        ReproError: another process holds it (two runs of one config into one folder would
            interleave their rows).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl
    except ImportError:  # not POSIX: the manifest's live-writer check only
        yield
        return
    fd = os.open(out_dir, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ReproError(f"{out_dir} is being written by another repro process; wait for "
                             "it or choose another --out") from None
        yield
    finally:
        os.close(fd)


@contextlib.contextmanager
def _parent_lock(parent: Path) -> Iterator[None]:
    """Wait for the exclusive flock on ``parent`` (the folder holding the targets): swaps,
    recoveries and the creation or removal of staging folders under it, one at a time."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no concurrent swaps to order
        yield
        return
    fd = os.open(parent, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _has_manifest(folder: Path) -> bool:
    return (folder / MANIFEST_NAME).is_file()


def _recover_locked(target: Path) -> str | None:
    """Finish or undo a swap of ``target`` that a killed process left half done (the parent
    lock held); what was done, or None if there was nothing to do."""
    backup = replaced_dir(target)
    if not backup.is_dir():
        return None
    if target.is_dir() and _has_manifest(target):  # the new run is in place: drop the old
        shutil.rmtree(backup, ignore_errors=True)
        return f"removed {backup} (a run replaced by {target}; its swap was cut short)"
    if target.is_dir() and any(target.iterdir()):
        return f"left {backup} aside: {target} holds files but no manifest; sort them out"
    if target.is_dir():
        target.rmdir()
    os.rename(backup, target)
    return f"restored {target} from {backup} (a swap was cut short before the new run came in)"


def _tidy(parent: Path) -> None:
    """Remove ``.partial`` and ``.replaced`` under ``parent`` when empty (parent lock held)."""
    for name in (PARTIAL_DIR, REPLACED_DIR):
        with contextlib.suppress(OSError):
            (Path(parent) / name).rmdir()


def recover(target: Path) -> str | None:
    """:func:`_recover_locked` under the parent lock (no swap of another process in flight)."""
    target = Path(target)
    if not (target.parent / REPLACED_DIR).is_dir():
        return None
    with _parent_lock(target.parent):
        done = _recover_locked(target)
        _tidy(target.parent)
    return done


def recover_all(parent: Path) -> list[str]:
    """:func:`recover` every target under ``parent`` that has a replaced run aside."""
    folder = Path(parent) / REPLACED_DIR
    if not folder.is_dir():
        return []
    with _parent_lock(Path(parent)):
        done = [d for p in sorted(folder.iterdir())
                if (d := _recover_locked(Path(parent) / p.name)) is not None]
        _tidy(Path(parent))
    return done


def _empty(folder: Path) -> None:
    """Remove everything in ``folder`` (a dead run's partial files; the folder is held)."""
    for path in folder.iterdir():
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()


def _swap(stage: Path, target: Path) -> None:
    """Put ``stage`` in ``target``'s place (parent lock held): target -> replaced, stage ->
    target, then remove the replaced run. The old run is removed only once the new one is
    in place; a failed second rename puts it back."""
    _recover_locked(target)  # a swap of this target killed since this run began
    if not (target.exists() or target.is_symlink()):
        os.rename(stage, target)
        return
    backup = replaced_dir(target)
    backup.parent.mkdir(exist_ok=True)
    os.rename(target, backup)
    try:
        os.rename(stage, target)
    except BaseException:
        os.rename(backup, target)
        raise
    shutil.rmtree(backup, ignore_errors=True)  # left over: the next recover() removes it


def _create(stage: Path) -> None:
    try:
        stage.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ReproError(f"cannot create the staging folder {stage}: "
                         f"{exc.strerror or exc}") from exc


@contextlib.contextmanager
def staged(target: Path) -> Iterator[Path]:
    """Write a run of ``target`` aside: yield its staging folder (locked, emptied of a dead
    run's files) and, when the block ends without an exception, swap it in for ``target``.

    An exception (a signal's KeyboardInterrupt, a crash) leaves ``target`` as it was and the
    partial run in the staging folder (removed instead if it holds no manifest: nothing was
    recorded). A killed process leaves the same, its manifest ``running`` (read as
    interrupted, :func:`repro.runs.trace.effective_manifest`).

    Raises:
        ReproError: another process is writing a run of ``target`` (its staging folder is
            locked), or the staging folder cannot be created.
    """
    from repro.runs.signals import deferred

    target = Path(target)
    parent, stage = target.parent, staging_dir(target)
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ReproError(f"cannot create {parent}: {exc.strerror or exc}") from exc
    with contextlib.ExitStack() as stack:
        with _parent_lock(parent):
            _recover_locked(target)
            _create(stage)
            stack.enter_context(run_folder_lock(stage))
        _empty(stage)
        try:
            yield stage
        except BaseException:
            if not _has_manifest(stage):
                with _parent_lock(parent):
                    shutil.rmtree(stage, ignore_errors=True)
                    _tidy(parent)
            raise
        with deferred(), _parent_lock(parent):
            _swap(stage, target)
            _tidy(parent)
