"""The command line's figures, drawn in a Python process of their own that starts with the command.

Importing matplotlib and drawing a first figure cost about 1 s of Python on a slow CPU: as long as a warm run of
`pamjax fit examples/fit_example.toml` spends fitting. A thread would hold Python's global lock against the fit's own
Python; a process does that work on another core while the fit runs, and then draws the figure it is sent. The
drawing module is run as a script (`python FILE`: it imports neither pamjax nor JAX) that warms up, waits for one
request on stdin and answers on stdout (`pamjax/_cli/fit_figure.py`). Where no process can be started, or it died,
the figure is drawn here, as before. Errors come back as the same exception types (`ModuleNotFoundError` without
matplotlib, `OSError` when the file cannot be written).
"""

import atexit
import builtins
import pickle
import subprocess
import sys
import threading

# The script without the script's folder on sys.path (pamjax/_cli's module names must not shadow a library's).
_RUN = "import runpy, sys; del sys.path[0]; runpy.run_path(sys.argv[1], run_name='__main__')"
_STATE = {}  # module name → its FigureProcess


class FigureProcess:
    """A started drawing process for `module` (a module with `draw(path, columns)` that serves as a script)."""

    def __init__(self, module):
        self.module = module
        self.sender = None  # the thread sending `prepare`'s columns
        try:
            self.proc = subprocess.Popen([sys.executable, "-c", _RUN, module.__file__], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        except OSError:
            self.proc = None

    def prepare(self, columns):
        """Send `columns` without their models ahead of the request (see `pamjax/_cli/fit_figure.py`), from a thread
        of its own (a large recording would fill the pipe before the process reads it); nothing if it is not
        running or `module` has no `prepare`."""
        if self.proc is None or not hasattr(self.module, "prepare") or self.sender is not None:
            return
        message = pickle.dumps({"prepare": columns}, protocol=pickle.HIGHEST_PROTOCOL)

        def send(stream=self.proc.stdin):
            try:
                stream.write(message)
                stream.flush()
            except (OSError, ValueError):  # the process died (the request then finds out): drawn here instead
                pass

        self.sender = threading.Thread(target=send, daemon=True)
        self.sender.start()

    def draw(self, path, columns):
        """Draw `columns` into `path` (in the process when it runs, else here)."""
        proc, self.proc = self.proc, None
        if self.sender is not None:
            self.sender.join()  # the process reads on: the prepared columns go first, whole
        if proc is not None:
            request = pickle.dumps({"path": str(path), "columns": columns}, protocol=pickle.HIGHEST_PROTOCOL)
            try:
                out, _ = proc.communicate(request, timeout=600)
            except (OSError, subprocess.TimeoutExpired):  # died before reading, or hangs: draw it here
                proc.kill()
                proc.wait()
                out = b""
            answer = out.decode(errors="replace").strip()
            if answer == "ok":
                return
            if answer:
                name, _, message = answer.partition("\t")
                kind = getattr(builtins, name, None)
                try:
                    error = kind(message) if isinstance(kind, type) and issubclass(kind, Exception) else None
                except TypeError:  # an exception type that takes other arguments
                    error = None
                raise error if error is not None else RuntimeError(f"{name}: {message}")
        self.module.draw(path, columns)

    def close(self):
        """Stop a process that was not used (at exit; it would also end by itself, its stdin closed)."""
        proc, self.proc = self.proc, None
        if proc is not None:
            proc.kill()
            proc.wait()
            for stream in (proc.stdin, proc.stdout, proc.stderr):
                stream.close()


def start(module):
    """Start the drawing process for `module` now, so that it is warm when its figure is drawn (once per process)."""
    if module.__name__ not in _STATE:
        process = _STATE[module.__name__] = FigureProcess(module)
        atexit.register(process.close)  # one a command started but did not use (it failed before its figure)
    return _STATE[module.__name__]


def prepare(module, columns):
    """Send `columns` without their models to `module`'s started process, to lay out its figure while the command
    works (`FigureProcess.prepare`); nothing where no process was started."""
    process = _STATE.get(module.__name__)
    if process is not None:
        process.prepare(columns)


def draw(module, path, columns):
    """Draw `columns` with `module`: in its started process if there is one, else here."""
    process = _STATE.pop(module.__name__, None)
    if process is None:
        module.draw(path, columns)
    else:
        process.draw(path, columns)
