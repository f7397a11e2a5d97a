"""The `pamjax` command line: `pamjax demo`, `pamjax fit CONFIG.toml`, `pamjax sweep CONFIG.toml`."""

import argparse
import importlib
import sys

# subcommand → (module, function, help). Each module defines `add_arguments(parser)` and `run(args)`.
_COMMANDS = {
    "demo": ("pamjax._demo", "Run paper 000's valve and system experiments with the preset; print and plot them."),
    "fit": ("pamjax._cli_fit", "Fit parameters to recordings as described by a TOML config."),
    "sweep": ("pamjax._cli_sweep", "Run a batch sweep described by a TOML config; write NPZ/CSV and a figure."),
}


def _split_cpu_for_sweep(argv):
    """`pamjax sweep` runs on one XLA CPU device per core by default (`--cpu-devices`), so that `sweep` shards its
    batch over every core. JAX takes the device count only before it first runs anything, which importing the
    subcommand modules does; so it is read from the command line here, before them."""
    if not argv or argv[0] != "sweep":
        return
    from ._cli_sweep import DEFAULT_CPU_DEVICES  # importing pamjax runs no JAX computation

    early = argparse.ArgumentParser(add_help=False)
    early.add_argument("--cpu-devices", type=int, default=DEFAULT_CPU_DEVICES)
    known, _ = early.parse_known_args(argv[1:])
    if known.cpu_devices >= 1:  # a bad value is reported by the full parser below
        import jax

        try:
            jax.config.update("jax_num_cpu_devices", known.cpu_devices)
        except RuntimeError:  # JAX already ran in this process (main() called from Python): its devices stay
            pass


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    _split_cpu_for_sweep(argv)
    parser = argparse.ArgumentParser(prog="pamjax", description="Differentiable pneumatic artificial muscle models.")
    sub = parser.add_subparsers(dest="command", required=True)
    available = {}
    for name, (module_name, help_text) in _COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as err:
            if err.name != module_name:
                raise
            continue
        p = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(p)
        available[name] = module
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)  # float64 physics (entry point, not an import-time side effect)
    return available[args.command].run(args) or 0


if __name__ == "__main__":
    sys.exit(main())
