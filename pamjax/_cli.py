"""The `pamjax` command line: `pamjax demo`, `pamjax fit CONFIG.toml`, `pamjax sweep CONFIG.toml`."""

import argparse
import importlib
import sys

# subcommand → (module, function, help). Each module defines `add_arguments(parser)` and `run(args)`.
_COMMANDS = {
    "demo": ("pamjax._demo", "Run paper 000's valve and system experiments with the preset; print and plot them."),
    "fit": ("pamjax._cli_fit", "Fit parameters to recordings as described by a TOML config."),
    "sweep": ("pamjax._cli_sweep", "Run a batch sweep described by a TOML config; write NPZ/CSV and a figure."),
    "design": ("pamjax._cli_design", "Design a PWM duty experiment by gradient; write the signal as CSV and a figure."),
}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
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
