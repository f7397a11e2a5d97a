"""The output folder of a `pamjax` command: checked, created, test-written and locked BEFORE any work, so that no
finished work is lost to a path that cannot take it; results written atomically, and to a named fallback file if
writing them fails at the end anyway.

    with OutputFolder(out, "pamjax fit", ["fit.json", "model.json", "fit.png"], overwrite=False) as folder:
        ...                                          # the work
        folder.write_text("fit.json", text)          # atomic; on failure: ./pamjax-rescued-fit-<time>-fit.json

Every refusal is a `PamjaxInputError` naming the path and the command-line flag that fixes it (`--out`,
`--overwrite`). The lock (`.pamjax.lock` in the folder, held with `flock`) stops a second pamjax from writing the
same folder while the first runs; the operating system releases it when a process ends, however it ends.
"""

import datetime
import json
import os
import pathlib
import signal
import socket
import tempfile
import time

from .._core.errors import PamjaxInputError

LOCK_NAME = ".pamjax.lock"
EXIT_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_TERMINATED = 2, 1, 130, 143  # exit statuses of the commands


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an interrupt so that a command stops as cleanly as on Ctrl-C (`pamjax._cli.main`)."""


def interrupt_status(err):
    """The exit status for an interrupt: 143 for SIGTERM, 130 for Ctrl-C (128 + the signal number)."""
    return EXIT_TERMINATED if isinstance(err, Terminated) else EXIT_INTERRUPTED


# Signals received by the command line (`pamjax._cli.main` records them). Python raises KeyboardInterrupt wherever the
# main thread happens to be, and one that lands in a garbage-collection callback (JAX registers one) is printed as
# "Exception ignored" and lost: `raise_pending` raises it again at the next safe point (each fit iteration).
PENDING = []


def raise_pending():
    """Raise the interrupt of a signal that was received but swallowed (see `PENDING`)."""
    if PENDING:
        signum = PENDING.pop()
        PENDING.clear()
        raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None
    import msvcrt


def _lock_fd(fd):
    if fcntl is not None:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    else:  # pragma: no cover
        msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)


def _unlock_fd(fd):
    if fcntl is not None:
        fcntl.flock(fd, fcntl.LOCK_UN)
    else:  # pragma: no cover
        msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)


class OutputFolder:
    """An output folder held for one command (a context manager; see the module docstring).

    **Arguments:** `path`; `command` (for messages and the lock, e.g. "pamjax fit"); `outputs`: the file names the
    command writes (an existing one is refused unless `overwrite`, or unless listed in `replaceable`); `flag`: the
    command-line option that names the folder; `stale`: what an earlier run of the command may have written that this
    one does not (a figure this run skips with --no-plot, an earlier --profile's profile.json): with `overwrite` (or
    every output `replaceable`: a resumed run's folder), the earlier results are replaced whole, so these are removed
    once the command has written its own (else they would read as this run's). Without `overwrite` one that exists
    is refused, as an existing output is (unless every output is `replaceable`). An `overwrite` run stopped after
    writing some outputs removes the earlier run's files it had not replaced yet, saying so; one stopped before
    writing any leaves the earlier results whole.
    """

    def __init__(self, path, command, outputs, *, overwrite=False, replaceable=(), flag="--out", stale=()):
        if path is None or str(path).strip() == "":
            raise PamjaxInputError(f"{command}: the output folder is empty; name one with {flag}")
        self.path = pathlib.Path(path)
        self.command, self.outputs, self.flag = command, list(outputs), flag
        self.overwrite, self.replaceable = overwrite, set(replaceable)
        self.stale = [name for name in stale if name not in self.outputs]
        self.failed = []  # (name, error, where it went instead)
        self.written = []  # the outputs this run has written, in order
        self._fd = None

    def __truediv__(self, name):
        return self.path / name

    # -- before the work ------------------------------------------------------------------------------------------
    def __enter__(self):
        self._create()
        self._test_write()
        self._lock()
        try:
            self._check_existing()
        except BaseException:
            self._unlock()
            raise
        return self

    def __exit__(self, exc_type, *exc):
        try:
            resumed = bool(self.outputs) and set(self.outputs) <= self.replaceable  # `fit --resume`: its own folder
            if exc_type is None and (self.overwrite or resumed) and not self.failed:  # the earlier results replaced
                for name in self.stale:  # whole: what this run did not write of them is removed, not left to read as
                    (self.path / name).unlink(missing_ok=True)  # its own (`fit --resume --no-plot`: the old fit.png)
            elif exc_type is not None and self.overwrite and self.written:
                self._drop_earlier()
        finally:
            self._unlock()
        return False

    def _drop_earlier(self):
        """An --overwrite run stopped after writing some of its outputs: the earlier run's files it had not replaced
        yet are removed (a new trajectory.csv beside the earlier run's figure read as one run's results), and one
        line says what the folder now holds."""
        earlier = [name for name in self.outputs + self.stale
                   if name not in self.written and (self.path / name).exists()]
        for name in earlier:
            try:
                (self.path / name).unlink()
            except OSError:
                pass
        print(f"{self.command}: stopped after writing {', '.join(self.written)} in {self.path}"
              + (f"; the earlier run's {', '.join(earlier)} removed (its results were being replaced)" if earlier
                 else ""), flush=True)

    def _refuse(self, what, err=None):
        reason = f" ({err.strerror or err})" if isinstance(err, OSError) else ""
        raise PamjaxInputError(f"{self.command}: {what}{reason}; choose another folder with {self.flag}")

    def _create(self):
        path = self.path
        if path.exists() and not path.is_dir():
            self._refuse(f"{self.flag} {path} is a file, not a folder")
        for parent in path.parents:
            if parent.exists() and not parent.is_dir():
                self._refuse(f"cannot create the output folder {path}: {parent} is a file")
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            self._refuse(f"cannot create the output folder {path}", err)

    def _test_write(self):
        probe = self.path / f".pamjax-write-test-{os.getpid()}"
        try:
            with open(probe, "wb") as f:
                f.write(b"pamjax write test\n" * 64)
                f.flush()
                os.fsync(f.fileno())
            probe.unlink()
        except OSError as err:
            try:
                probe.unlink(missing_ok=True)
            except OSError:
                pass
            self._refuse(f"cannot write to the output folder {self.path}", err)

    def _lock(self):
        path = self.path / LOCK_NAME
        for _ in range(10):  # retry if another process removed the lock file between our open and flock
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as err:
                self._refuse(f"cannot create the lock file {path}", err)
            try:
                _lock_fd(fd)
            except OSError:
                holder = _read_holder(fd)
                os.close(fd)
                raise PamjaxInputError(
                    f"{self.command}: {self.path} is in use by another pamjax ({holder}); wait for it to finish, or "
                    f"choose another folder with {self.flag}"
                ) from None
            try:
                same = os.fstat(fd).st_ino == os.stat(path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                info = {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command,
                        "started": datetime.datetime.now().isoformat(timespec="seconds")}
                os.write(fd, json.dumps(info).encode())
                self._fd = fd
                return
            os.close(fd)
        self._refuse(f"cannot lock {path}")

    def _unlock(self):
        if self._fd is None:
            return
        try:
            (self.path / LOCK_NAME).unlink(missing_ok=True)
        except OSError:
            pass
        try:
            _unlock_fd(self._fd)
        finally:
            os.close(self._fd)
            self._fd = None

    def _check_existing(self):
        if self.overwrite:
            return
        for name in self.outputs:
            if (self.path / name).exists() and name not in self.replaceable:
                raise PamjaxInputError(f"{self.command}: {self.path / name} exists; pass --overwrite to replace it, or "
                                       f"choose another folder with {self.flag}")
        # An earlier run's file that this one does not write (its figure, left by a run with --no-plot) would sit
        # beside this run's results as if it were theirs (`pamjax simulate --no-plot` into a folder holding only an
        # old trajectory.png wrote a new CSV next to it): refused as the outputs are. Not where every output is
        # replaceable (`pamjax fit --resume`: the folder holds the resumed run's own files, and --overwrite, which
        # would remove them, is not given with --resume).
        if self.outputs and set(self.outputs) <= self.replaceable:
            return
        for name in self.stale:
            if (self.path / name).exists() and name not in self.replaceable:
                raise PamjaxInputError(f"{self.command}: {self.path / name} exists, an earlier run's that this one "
                                       "would not replace; pass --overwrite to replace the earlier results whole "
                                       f"(it is then removed), or choose another folder with {self.flag}")

    # -- after the work -------------------------------------------------------------------------------------------
    def write_text(self, name, text):
        return self.write(name, lambda p: pathlib.Path(p).write_text(text, encoding="utf-8"))

    def write(self, name, writer):
        """Write output `name` with `writer(path)` into a temporary file renamed into place (a reader never sees half
        a file). If that fails, the result goes to a fallback file (current folder, else the system's temporary
        folder), named in a message; returns the path written, or None if even that failed."""
        target = self.path / name
        tmp = self.path / f".{name}.tmp-{os.getpid()}{pathlib.Path(name).suffix}"
        try:
            writer(tmp)
            os.replace(tmp, target)
            self.written.append(name)
            return target
        except OSError as err:
            try:
                tmp.unlink(missing_ok=True)
            except OSError:
                pass
            return self._rescue(name, writer, err)

    def _rescue(self, name, writer, err):
        stamp = time.strftime("%Y%m%d-%H%M%S")
        command = self.command.split()[-1]
        for folder in (pathlib.Path.cwd(), pathlib.Path(tempfile.gettempdir()), pathlib.Path.home()):
            fallback = folder / f"pamjax-rescued-{command}-{stamp}-{name}"
            try:
                writer(fallback)
            except OSError:
                continue
            self.failed.append((name, err, fallback))
            print(f"{self.command}: could not write {self.path / name} ({err.strerror or err}); saved it as "
                  f"{fallback} instead", flush=True)
            return fallback
        self.failed.append((name, err, None))
        print(f"{self.command}: could not write {self.path / name} ({err.strerror or err}), nor a fallback copy",
              flush=True)
        return None


def _read_holder(fd):
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        info = json.loads(os.read(fd, 4096).decode() or "{}")
        return f"{info.get('command', 'pamjax')}, pid {info.get('pid', '?')} on {info.get('host', '?')}, since " \
               f"{info.get('started', '?')}"
    except (OSError, ValueError):
        return "lock held"
