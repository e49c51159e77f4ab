"""Command-line arguments of the process mains, checked where argparse parses them.

Every numeric flag is finite and in range, every output path can be written before the run
starts, and a bad one ends the program with exit code 2 and one line naming the flag:

    simulator: error: argument --step-timeout: must be a finite number > 0, got 'nan'

Not math: the mains' edge. It imports argparse, math and os only (no sockets, no files opened).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

BAD_ARGUMENTS = 2  # exit code of every main for a bad configuration or argument


# what every process main's exit code means (README, docs/reference/commands.md); each main's
# --help lists the ones it can return with `exit_codes`
EXIT_CODE_MEANINGS = {
    0: "success",
    1: "a link or process failure",
    2: "bad configuration or arguments (the message names the file, key or flag)",
    3: "scenario mismatch between a companion and the simulator",
    4: "the mission failed (the verdict says why)",
    130: "interrupted (SIGINT or SIGTERM)",
}


def exit_codes(*codes: int, **meanings: str) -> str:
    """An --help epilog listing `codes` with their meanings (EXIT_CODE_MEANINGS, or the
    command's own words given as c<code>="...")."""
    parts = [f"{c} {meanings.get(f'c{c}', EXIT_CODE_MEANINGS[c])}" for c in codes]
    return "Exit codes: " + "; ".join(parts) + "."


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """--help gives every option's default: "(default: ...)" is added to each help text that
    does not already say its default, for every option and optional positional with a value
    (not for flags, and not where the default is None or empty: "not given" is then what the
    help text describes)."""

    def _get_help_string(self, action):
        text = action.help or ""
        optional = bool(action.option_strings) or action.nargs in (argparse.OPTIONAL, argparse.ZERO_OR_MORE)
        if ("default" in text.lower() or not optional or action.default in (None, False, [], ())
                or action.default is argparse.SUPPRESS or action.nargs == 0):
            return text
        return f"{text} (default: %(default)s)"


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but an error is one line (`prog: error: ...`, exit 2) without the usage block,
    and --help gives every default (`DefaultsHelpFormatter`)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", DefaultsHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):  # noqa: D401 - argparse's hook
        self.exit(BAD_ARGUMENTS, f"{self.prog}: error: {message}\n")


def number(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
           integer: bool = False, unit: str = "") -> Callable[[str], float]:  # fmt: skip
    """An argparse type: a finite number (an integer if `integer`) >= lo (> lo if `lo_open`)
    and <= hi. NaN and infinities are refused."""
    bounds = []
    if lo is not None:
        bounds.append(f"{'>' if lo_open else '>='} {lo:g}")
    if hi is not None:
        bounds.append(f"<= {hi:g}")
    want = f"{'an integer' if integer else 'a finite number'}{' ' if bounds else ''}{' and '.join(bounds)}{unit}"

    def parse(text: str) -> float:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {want}, got {text!r}") from None
        ok = math.isfinite(value) and (lo is None or (value > lo if lo_open else value >= lo)) \
            and (hi is None or value <= hi)
        if not ok:
            raise argparse.ArgumentTypeError(f"must be {want}, got {text!r}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


# the common kinds
seconds = number(0.0, lo_open=True, unit=" s")  # a timeout or a duration
seconds_or_zero = number(0.0, unit=" s")
count = number(1, integer=True)  # a positive integer


def output_dir(text: str) -> Path:
    """An argparse type: a folder that is or can be created and written (checked now, before the run)."""
    path = Path(text)
    if path.exists():
        if not path.is_dir():
            raise argparse.ArgumentTypeError(f"{text}: exists and is not a folder")
        if not os.access(path, os.W_OK | os.X_OK):
            raise argparse.ArgumentTypeError(f"{text}: folder not writable")
        return path
    _creatable(path, text)
    return path


def output_file(text: str) -> Path:
    """An argparse type: a file that can be written (its folder exists or can be created, and is
    writable; the path is not a folder). Checked now, before the run."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: is a folder, not a file")
    if path.exists():
        if not os.access(path, os.W_OK):
            raise argparse.ArgumentTypeError(f"{text}: not writable")
        return path
    _creatable(path, text)
    return path


def _creatable(path: Path, text: str) -> None:
    """The nearest existing ancestor of `path` is a writable folder."""
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text}: cannot create it, {parent} is not writable")
    try:  # os.access says yes to root everywhere (/proc, say): a nameless file tells
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"{text}: cannot create it: {parent} takes no new files "
                                         f"({exc.strerror or exc})") from None


def fail(prog: str, message: str) -> int:
    """Print `prog: error: message` (one line) and return the bad-arguments exit code."""
    print(f"{prog}: error: {message}", file=sys.stderr)
    return BAD_ARGUMENTS
