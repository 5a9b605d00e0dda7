"""The ``flagsim`` command (also ``python -m flagsim``): ``flagsim COMMAND [options]``.

Sub-commands live in their own modules, listed in ``COMMANDS`` and imported only when their
command runs (or its --help is asked for). A command module defines

    configure(parser)  add its arguments to an argparse.ArgumentParser
    run(args) -> int   do the work; return the exit code

and its docstring is the command's --help description. To add a command, add a module and a
line to COMMANDS. User errors (bad input, missing programs, failed frames) print one line,
``flagsim: error: ...``, and exit non-zero without a traceback (FLAGSIM_TRACEBACK=1 shows it).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

#: name -> (module, one-line summary), in the order --help lists them
COMMANDS = {
    "run": (
        "flagsim.commands.run",
        "simulate a scene and export it for POV-Ray (--render: render it to a GIF/MP4)",
    ),
    "render": ("flagsim.commands.render", "render an existing export with POV-Ray"),
    "view": (
        "flagsim.commands.view",
        "watch a scene live in a window (--screenshot: a picture drawn off-screen)",
    ),
    "scenes": ("flagsim.commands.scenes", "list the built-in scenes"),
    "study": (
        "flagsim.commands.study",
        "accuracy (error against run time) or stability (stiff and extreme cases) study",
    ),
    "sweep": (
        "flagsim.commands.sweep",
        "run a scene under every combination of some settings (--render: render each)",
    ),
}

EXIT_OK = 0
EXIT_FAILURE = 1  # the work failed: frames did not render, the simulation diverged, I/O
EXIT_USAGE = 2  # the input is wrong: arguments, scene name or file, TOML keys, texture
EXIT_INTERRUPTED = 130


def _top_parser():
    width = max(len(name) for name in COMMANDS)
    listing = "\n".join(f"  {name:<{width}}  {summary}" for name, (_, summary) in COMMANDS.items())
    from . import __version__

    p = argparse.ArgumentParser(
        prog="flagsim",
        description="Simulate flags whipped by the wind and render them with POV-Ray.",
        epilog=f"commands:\n{listing}\n\n'flagsim COMMAND --help' describes a command.\n"
        "example:  flagsim run paper --seconds 4 --fps 25 --out out/demo --render --gif",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"flagsim {__version__}")
    p.add_argument("command", metavar="COMMAND", nargs="?", help="one of: " + ", ".join(COMMANDS))
    p.add_argument("args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    return p


def command_parser(name):
    """(module, parser) of a sub-command, importing its module."""
    module = importlib.import_module(COMMANDS[name][0])
    parser = argparse.ArgumentParser(
        prog=f"flagsim {name}",
        description=module.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    module.configure(parser)
    return module, parser


def error(message, code):
    print(f"flagsim: error: {message}", file=sys.stderr)
    return code


def main(argv=None):
    """Entry point of the console script; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    top = _top_parser()
    ns = top.parse_args(argv)
    if ns.command is None:
        top.print_help(sys.stderr)
        return EXIT_USAGE
    if ns.command not in COMMANDS:
        top.print_usage(sys.stderr)
        return error(
            f"unknown command '{ns.command}' (choose from {', '.join(COMMANDS)})", EXIT_USAGE
        )
    module, parser = command_parser(ns.command)
    args = parser.parse_args(ns.args)
    if os.environ.get("FLAGSIM_TRACEBACK"):
        return module.run(args)
    return run_guarded(module.run, args)


class CommandError(Exception):
    """A command could not do its work for a reason the user can act on (exit code 1)."""


def run_guarded(fn, args):
    """Run a command, turning the errors a user can act on into one line and an exit code."""
    import flagsim

    from ._pool import DaskNotInstalled
    from .povray.render import FfmpegNotFound, PovrayNotFound, RenderError
    from .study.runner import TaskFailed

    try:
        return fn(args)
    except KeyboardInterrupt:
        print("\nflagsim: interrupted (run the same command again to resume)", file=sys.stderr)
        return EXIT_INTERRUPTED
    except flagsim.DivergenceError as e:
        return error(f"the simulation diverged: {e}", EXIT_FAILURE)
    except (
        PovrayNotFound,
        FfmpegNotFound,
        RenderError,
        CommandError,
        TaskFailed,
        DaskNotInstalled,
    ) as e:
        return error(str(e), EXIT_FAILURE)
    except ValueError as e:  # invalid scene, TOML key, argument value, export conflict
        return error(str(e), EXIT_USAGE)
    except FileNotFoundError as e:  # a scene file or texture that is not there
        return error(str(e), EXIT_USAGE)
    except OSError as e:  # disk full, permissions, ...
        return error(str(e), EXIT_FAILURE)


if __name__ == "__main__":
    sys.exit(main())
