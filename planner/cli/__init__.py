"""``lrauv``: the one console command. Parses, calls one library function, maps errors to exit codes.

Each subcommand is a module (``TABLE``) with ``add_parser(subparsers)`` and ``run(args) -> int``;
only the module of the subcommand given is imported, so ``lrauv exec`` never loads the
planner's heavy dependencies. The subcommand modules import nothing heavy at module level
either: ``build_parser`` (the whole parser, for tests and documentation) loads them all.

Bad input prints one line ``lrauv: error: ...`` to stderr and exits with status 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import import_module
from typing import Any

from planner.cli.help_text import UserHelp, describe
from planner.contract.arguments import CommandParser
from planner.contract.errors import LrauvError

EXIT_BAD_INPUT = 2
EXIT_BROKEN_PIPE = 128 + 13  # as a shell reports a process that SIGPIPE ended (Python ignores the signal)


@dataclass(frozen=True, slots=True)
class Command:
    """One subcommand: its name, the module that registers and runs it, its one-line help."""

    name: str
    module: str
    help: str


# In the order ``lrauv --help`` lists them. ``executive.cli`` registers and runs both exec and log.
TABLE: tuple[Command, ...] = (
    Command("plan", "planner.cli.plan", "plan a feedback policy and write the policy table"),
    Command("forecast", "planner.cli.forecast", "inspect or generate forecasts"),
    Command("evaluate", "planner.cli.evaluate", "Monte Carlo closed-loop comparison of plans over a truth field"),
    Command("batch", "planner.cli.batch", "plan every goal of many missions (or a fleet file) as parallel tasks"),
    Command("holdout", "planner.cli.holdout",
            "ensemble plan against single-member plans, each flown in a member it did not see"),
    Command("exec", "executive.cli", "run the onboard executive against a vehicle over MAVLink"),
    Command("log", "executive.cli", "MCAP log tools"),
    Command("sim", "vehicle_sim.cli", "run the simulated ArduSub-like vehicle (MAVLink 2 over UDP)"),
    Command("demo", "planner.cli.demo", "run the simulated vehicle and the executive over UDP to the goal"),
    Command("upload", "planner.cli.upload", "upload a mission's goals and tables to a running executive over MAVLink"),
    Command("waypoints", "planner.cli.waypoints", "export or import goals as QGC WPL 110 waypoint files"),
    Command("replay", "planner.cli.replay", "summarise, audit, report, export or re-stream a dive's MCAP log"),
)
COMMANDS = {c.name: c for c in TABLE}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``lrauv`` parser: every subcommand's module registers its own options.

    With ``command``, only that subcommand's module is imported; the others are listed by
    name and help alone (enough for ``lrauv --help`` and for naming a wrong subcommand).
    """
    parser = CommandParser(prog="lrauv", description="Feedback motion planning and onboard execution for long-range AUVs.",
                           formatter_class=UserHelp)
    parser.add_argument("--version", action=_Version, nargs=0, help="print the installed version and exit")
    sub = parser.add_subparsers(dest="command", required=True)
    wanted = None if command is None else COMMANDS[command].module
    for c in TABLE:
        if c.name in sub.choices:  # registered by an earlier entry's module
            continue
        if wanted in (None, c.module):
            import_module(c.module).add_parser(sub)
        else:
            sub.add_parser(c.name, help=c.help)
    describe(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``lrauv``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(_command_in(argv)).parse_args(argv)
    try:
        status = _module(args.command).run(args)
        sys.stdout.flush()  # here, where a reader that went away is caught (below), not at the interpreter's exit
        return status
    except BrokenPipeError as exc:
        if not _stdout_reader_gone():  # another pipe or socket of the command: an error like any other
            print(f"lrauv: error: {exc.filename or 'a pipe'}: {exc.strerror or exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        # stdout's reader stopped reading (`| head`): not bad input, and the work is done.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit's own flush must not fail again
        return EXIT_BROKEN_PIPE
    except LrauvError as exc:
        print(f"lrauv: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:  # a file we were told to read or write
        where = exc.filename or "file"
        print(f"lrauv: error: {where}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError as exc:  # a grid, region or forecast too large for this machine
        print(f"lrauv: error: not enough memory: {str(exc) or 'an allocation failed'}; a smaller grid, region or time "
              "span?", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("lrauv: interrupted", file=sys.stderr)
        return 130


class _Version(argparse.Action):
    """``--version``: the installed distribution's version (pyproject.toml), looked up only when asked for."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        from importlib.metadata import PackageNotFoundError, version

        try:
            text = version("lrauv-feedback")
        except PackageNotFoundError:
            text = "unknown (not installed)"
        print(f"lrauv {text}")
        parser.exit()


def _stdout_reader_gone() -> bool:
    """Whether stdout is a pipe whose reading end is closed (poll reports an error on its writing end)."""
    import select

    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _fd, events in poller.poll(0))
    except (OSError, ValueError, AttributeError):  # no poll here, or stdout is no file
        return False


def _command_in(argv: Sequence[str]) -> str | None:
    """The subcommand named in ``argv``: its first word that is not an option (``lrauv`` has only ``-h`` and ``--version``)."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return word if word in COMMANDS else None


def _module(name: str) -> Any:
    return import_module(COMMANDS[name].module)


if __name__ == "__main__":
    sys.exit(main())
