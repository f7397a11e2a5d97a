"""The `pamjax` command line: `pamjax demo`, `pamjax fit CONFIG.toml`, `pamjax simulate CONFIG.toml`,
`pamjax sweep CONFIG.toml`.

A user error (a bad config, file, unit or path) prints one message — file and line for TOML, key, value and expected
range for values — and exits with status 2; a failed solve exits with 1; Ctrl-C (or SIGTERM) exits with 130 (143)
after one line saying what was kept. No traceback unless `--debug` (or the environment variable `PAMJAX_DEBUG=1`)
asks for it. `docs/cli.md` describes the commands and their files.
"""

import _imp
import argparse
import contextlib
import gc
import importlib
import os
import re
import signal
import sys
import threading

from .out import EXIT_FAILED, EXIT_INPUT, PENDING, Terminated, interrupt_status, raise_pending

# subcommand → (module, help). Each module defines `add_arguments(parser)` and `run(args)`.
_COMMANDS = {
    "demo": ("pamjax._cli.demo",
             "Run paper 000's valve and system experiments with the preset; write CSV and a figure."),
    "fit": ("pamjax._cli.fit", "Fit parameters to recordings as described by a TOML config; write the fitted model."),
    "simulate": ("pamjax._cli.simulate", "Simulate any model with any input; write the trajectory (CSV) and a figure."),
    "sweep": ("pamjax._cli.sweep", "Run a batch sweep described by a TOML config; write NPZ/CSV and a figure."),
    "design": ("pamjax._cli.design",
               "Design a PWM duty experiment by gradient; write the signal as CSV and a figure."),
    "reproduce": ("pamjax._cli.reproduce",
                  "Reproduce every item of papers 000 and 001 (pamjax.gallery); index page."),
}
DEBUG_VARIABLE = "PAMJAX_DEBUG"
_BATCHED = {"sweep"}  # commands whose work is batched lanes (an accelerator's); the others run single trajectories


@contextlib.contextmanager
def _signals_as_interrupts():
    """Ctrl-C and SIGTERM raise an interrupt (`Terminated` for SIGTERM) and are recorded in `PENDING`, so that one
    swallowed by a garbage-collection callback is raised again at the next safe point (`raise_pending`)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if _imp.lock_held():  # inside the import machinery's critical section (e.g. a weakref callback there, whose
            # exception Python swallows): an interrupt raised now would leave the global import lock held for good,
            # and the next import of another thread (a fit's beside-import, a compile thread) would wait forever.
            # The signal is sent again in 20 ms, when the lock is free (seen: `pamjax fit` hung on SIGINT).
            threading.Timer(0.02, os.kill, (os.getpid(), signum)).start()
            return
        PENDING.append(signum)
        raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()

    def unraisable(info):  # an interrupt swallowed in a callback: no "Exception ignored" traceback; it is pending
        if not isinstance(info.exc_value, KeyboardInterrupt):
            previous_hook(info)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    previous_hook, sys.unraisablehook = sys.unraisablehook, unraisable
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        sys.unraisablehook = previous_hook
        PENDING.clear()


def _common(suppress):
    """The flags every command takes, before or after its name (`pamjax --no-cache fit ...` = `pamjax fit --no-cache
    ...`). The main parser holds their defaults; each subparser's copy has none (`argparse.SUPPRESS`), so a flag given
    before the command is not reset by the subparser, and one given after it wins. Both copies refuse a bad value."""
    common = argparse.ArgumentParser(add_help=False)
    off, auto = (argparse.SUPPRESS, argparse.SUPPRESS) if suppress else (False, "auto")
    common.add_argument("--debug", action="store_true", default=off,
                        help=f"show Python tracebacks (also: environment variable {DEBUG_VARIABLE}=1; 0 or unset: "
                             "off)")
    common.add_argument("--device", choices=("auto", "cpu", "gpu", "tpu"), default=auto,
                        help="where the work runs: auto (default: single-trajectory commands on the CPU, where "
                             "they run fastest; sweeps on a GPU/TPU if there is one, else every CPU core), or cpu, "
                             "gpu, tpu to choose (docs/performance.md)")
    common.add_argument("--no-cache", action="store_true", default=off,
                        help="use no compilation cache: neither pamjax's nor JAX's persistent one (default: on, in "
                             "the user's cache directory; PAMJAX_CACHE_DIR moves it, PAMJAX_COMPILATION_CACHE=0 "
                             "turns it off)")
    return common


def _parser():
    parser = argparse.ArgumentParser(prog="pamjax", description="Differentiable pneumatic artificial muscle models.",
                                     parents=[_common(suppress=False)])
    sub = parser.add_subparsers(dest="command", required=True)
    common = _common(suppress=True)
    modules = {}
    for name, (module_name, help_text) in _COMMANDS.items():
        module = importlib.import_module(module_name)
        p = sub.add_parser(name, help=help_text, description=help_text, parents=[common])
        module.add_arguments(p)
        modules[name] = module
    return parser, modules


# A failed solve's advice is worded for the Python API (pamjax._solve.hints, shared with `pamjax.simulate`); `pamjax
# simulate` names the [simulate] keys instead (max_steps = 16384, stepping = "pwm", solver = "Rodas5") and drops what
# only the API has (throw=False).
_SIMULATE_ADVICE = (
    (r"\b([Pp])ass (?=(max_steps|substeps|solver|grid_step)=)", lambda m: "Set " if m[1] == "P" else "set "),
    (r"\b(set|Set) (max_steps|substeps)=([\d,]+)", lambda m: f"{m[1]} [simulate] {m[2]} = {m[3].replace(',', '')}"),
    (r"\b(set|Set) grid_step=([\d.eE+-]*\d)", r"\1 [simulate] grid_step = \2"),
    (r"\bsolver=pamjax\.(\w+)\(\)", r'[simulate] solver = "\1"'),
    (r"\bstepping='(\w+)'", r'[simulate] stepping = "\1"'),
    (r" ?\(throw=False [^)]*\)", ""),
    (r"[.;] ?(Pass|pass|simulate with) throw=False[^.]*", ""),
)


def _in_config_terms(command, text):
    """`text` (a solve's failure) with its advice in the config's terms where the command's config has the keys."""
    text = str(text)
    if command == "simulate":
        for pattern, replacement in _SIMULATE_ADVICE:
            text = re.sub(pattern, replacement, text)
    return text


def _say(command, text):
    text = re.sub(rf"^pamjax {command}( --\w+)?: ", "", str(text))
    print(f"pamjax {command}: error: {text}", file=sys.stderr, flush=True)


def main(argv=None):
    """Run the `pamjax` command line with `argv`; returns the exit status. Without `argv`, as the `pamjax` program
    and `python -m pamjax` call it, it runs `sys.argv[1:]` and then ends the process (`_end_process`)."""
    status = _main(sys.argv[1:] if argv is None else list(argv), program=argv is None)
    if argv is None:
        _end_process(status)
    return status


def _collect_less():
    """Python's cyclic garbage collector, set for a short process that traces JAX programs: what the imports made is
    frozen (never walked again) and young objects are collected every 50,000 allocations instead of 700. Tracing
    makes millions of short-lived objects, so with CPython's defaults a cold `pamjax fit examples/fit_example.toml`
    spent 0.28-0.42 s in ~590 collections (four of them full ones over every imported module); with this, 0.12-0.16
    s in ~280, nearly all of them during the imports, before this runs (docs/performance.md). Only for the
    command's own process (`main()` without arguments): a program that calls `main(argv)` keeps its own settings.
    No collection before the freeze: it costs ~45 ms, more than the little the imports leave behind."""
    gc.freeze()
    gc.set_threshold(50_000, 20, 100)


def _end_process(status):
    """End the process now, with `status`, once every output is written: non-daemon threads joined, the atexit
    handlers run (JAX's included), stdout and stderr flushed; what is skipped is the interpreter's teardown of its
    modules and objects (JAX, XLA's executables, equinox's classes: 0.4-0.7 s of a warm `pamjax fit` on a slow
    CPU, longer than the fit itself)."""
    for thread in threading.enumerate():
        if thread is not threading.current_thread() and not thread.daemon:
            thread.join()
    import atexit

    atexit._run_exitfuncs()  # noqa: SLF001 - the standard library's own exit path (what `sys.exit` would run)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(int(status) if isinstance(status, int) else 1)


def _settings(args):
    """Read the environment's settings before any work, and return whether to show tracebacks (`--debug`,
    `PAMJAX_DEBUG`); turn the compilation cache on or off; refuse `--out ""` (`Path("")` is the current folder: an
    unset `--out "$DIR"` fell back to results/... in simulate, sweep, fit and design). An on/off variable is read by
    `env_flag` (`PAMJAX_DEBUG=false` turned the tracebacks on); those `xla_cpu` reads at import are checked here,
    so that a value they do not take ("disabled", read there as on) is named rather than guessed."""
    from .._core.cache import cache_disabled, disable_compilation_cache, enable_compilation_cache
    from .._core.env import env_flag
    from .._core.errors import PamjaxInputError
    from .._core.xla_cpu import FAST_COMPILE, OPT_OUT

    debug = args.debug or env_flag(DEBUG_VARIABLE, False)
    for name in (FAST_COMPILE, OPT_OUT):
        env_flag(name, True)
    out = getattr(args, "out", None)
    if out is not None and not str(out).strip():
        raise PamjaxInputError(f"pamjax {args.command}: the output folder is empty; name one with --out")
    if args.no_cache or cache_disabled():  # off: JAX's own too, even where JAX_COMPILATION_CACHE_DIR turned it on
        disable_compilation_cache()
    else:  # a second run of a workflow loads its compiled programs instead of compiling (_core/cache.py)
        enable_compilation_cache()
    return debug


def _main(argv, program=False):
    parser, modules = _parser()
    args = parser.parse_args(argv)
    if program:  # the command's own process (not a program that calls main(argv)): set it up for the work
        _collect_less()
        if args.command != "sweep":  # single trajectories: XLA's classic CPU emitters compile them faster (xla_cpu)
            from .._core.xla_cpu import prefer_fast_compilation

            prefer_fast_compilation()
    import jax

    jax.config.update("jax_enable_x64", True)  # float64 physics (entry point, not an import-time side effect)
    from .._core.cache import announce_compilation
    from .._core.errors import PamjaxInputError, PamjaxSolveError

    command = args.command
    try:
        debug = _settings(args)
    except PamjaxInputError as err:  # a bad environment variable or --out "": named, before any work (status 2)
        if args.debug:
            raise
        _say(command, err)
        return EXIT_INPUT
    started = False  # whether the command's own work began (before it, an interrupt has nothing to keep)
    with _signals_as_interrupts():
        try:
            from .._core.devices import for_command

            # single trajectories on the CPU, sweeps on an accelerator if any (pamjax/_core/devices.py); said first
            placed, where = for_command("batched" if command in _BATCHED else "single", args.device,
                                        check=not getattr(args, "distributed", False))  # joins before JAX starts
            print(f"pamjax {command}: {where}", flush=True)
            # fit says itself when it compiles (its programs are known); the others are announced from outside
            announce = contextlib.nullcontext() if command == "fit" else announce_compilation(f"pamjax {command}")
            with placed, announce:
                started = True
                status = modules[command].run(args) or 0
            raise_pending()  # a signal swallowed while JAX was busy: the command finished, but say so
            return status
        except KeyboardInterrupt as err:
            if debug:
                raise
            terminated = isinstance(err, Terminated)
            note = "" if started else " before it started: nothing to resume, nothing written"
            print(f"pamjax {command}: {'terminated' if terminated else 'interrupted'}{note}", file=sys.stderr,
                  flush=True)
            return interrupt_status(err)
        except (PamjaxInputError, FileExistsError) as err:
            if debug:
                raise
            _say(command, err)
            return EXIT_INPUT
        except PamjaxSolveError as err:
            if debug:
                raise
            _say(command, _in_config_terms(command, err))
            return EXIT_FAILED
        except OSError as err:  # a file that cannot be read or written
            if debug:
                raise
            text = err.strerror or str(err)  # the file named once: a message that names it already is left whole
            _say(command, f"{text}: {err.filename}" if err.filename and str(err.filename) not in text else text)
            return EXIT_FAILED
        except Exception as err:  # not a user error: one line, the traceback on request
            if debug:
                raise
            first = str(err).strip().splitlines()[0] if str(err).strip() else ""
            _say(command, f"{type(err).__name__}: {first}\n(run again with --debug, or {DEBUG_VARIABLE}=1, to see "
                          "the traceback; if your input is valid, please report it)")
            return EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
