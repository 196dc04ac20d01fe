"""What ``cadra1`` and ``cadra2`` share: the help formatter that shows every option's default,
``-q``/``-v``/``--version``, warnings and the console exit conventions (docs/cli.md).
``value ± sigma`` has its one home in :func:`cadra.numfmt.pm`, below every layer.
"""

from __future__ import annotations

import argparse
import codecs
import os
import re
import sys
from contextlib import suppress

import cadra


def number(kind=float, low=None, high=None, *, above=False):
    """An argparse ``type`` for a numeric option: a finite ``kind`` (``int``: a whole number)
    in ``[low, high]`` (``above``: strictly above ``low``); anything else is a usage error
    naming the option, e.g. ``argument --max-iterations: must be a whole number >= 1, not
    -5``."""
    import math

    what = "a whole number" if kind is int else "a finite number"
    bounds = []
    if low is not None:
        bounds.append(f"{'>' if above else '>='} {low:g}")
    if high is not None:
        bounds.append(f"<= {high:g}")
    wanted = f"{what} {' and '.join(bounds)}".strip()

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {wanted}, not {text!r}") from None
        ok = math.isfinite(value) and (low is None or (value > low if above else value >= low))
        if not ok or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be {wanted}, not {text}")
        return value

    parse.__name__ = kind.__name__   # argparse names the type in some messages
    return parse


def write_error(exc: OSError) -> str:
    """Why a write failed, without the hidden temporary's path the error names (the message
    names the output the user gave): ``No space left on device``, ``Permission denied``."""
    return exc.strerror or type(exc).__name__


def warn(prog: str, text: str) -> None:
    """A warning on a result (a chi^2/nu far above 1, one shot given to the quasi-linear step,
    a parameter at a bound): one line on stderr, ``PROG: warning: TEXT``, never hidden by
    ``-q`` (which hides progress and chatter only; docs/cli.md)."""
    print(f"{prog}: warning: {text}", file=sys.stderr)


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's defaults formatter, but: a required option says ``(required)``, a default
    the help text already states is not repeated, and None or off reads ``none``/``off``."""

    def _get_help_string(self, action):
        text = action.help or ""
        if action.default is argparse.SUPPRESS or not action.option_strings \
                or isinstance(action, (argparse._HelpAction, argparse._VersionAction)):
            return text
        if action.required:
            return f"{text} (required)"
        if "default" in text.lower():
            return text
        if action.default is None:
            return f"{text} (default: none)"
        if action.default is False:
            return f"{text} (default: off)"
        return f"{text} (default: %(default)s)"


def add_verbosity(parser: argparse.ArgumentParser, *, top: bool = True) -> None:
    """``-q``/``--quiet`` and ``-v``/``--verbose`` (mutually exclusive). Subcommands pass
    ``top=False``: their defaults are suppressed so a flag given before the subcommand
    (``cadra2 -q fit ...``) is not reset by the subcommand's parser."""
    default = False if top else argparse.SUPPRESS
    g = parser.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true", default=default,
                   help="no progress bars or chatter: only the result or status line, "
                        "warnings and errors")
    g.add_argument("-v", "--verbose", action="store_true", default=default,
                   help="more detail (per-station, per-phase, per-shot lines)")


def add_version(parser: argparse.ArgumentParser) -> None:
    """``--version``: the program name and ``cadra.__version__``."""
    parser.add_argument("--version", action="version",
                        version=f"%(prog)s {cadra.__version__}")


#: a comma-separated list of numbers, the first negative (argparse takes it for an option)
_UNSIGNED = r"(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUMBER_LIST = re.compile(rf"^-{_UNSIGNED}(?:,\s*[-+]?{_UNSIGNED})*,?$")


def join_number_lists(argv: list[str], options: tuple[str, ...]) -> list[str]:
    """``--values -1.0,-1.5`` -> ``--values=-1.0,-1.5`` for the given options, so argparse does
    not take a negative number list for an option (a single negative number it already
    accepts). Other tokens are left alone."""
    out: list[str] = []
    k = 0
    while k < len(argv):
        tok = argv[k]
        if tok == "--":
            out += argv[k:]
            break
        if tok in options and k + 1 < len(argv) and _NUMBER_LIST.match(argv[k + 1]):
            out.append(f"{tok}={argv[k + 1]}")
            k += 2
            continue
        out.append(tok)
        k += 1
    return out


#: exit status when the reader of stdout went away (``cadra2 models | head -1``): 128 + SIGPIPE
EXIT_STDOUT_CLOSED = 141


def stdout_closed() -> int:
    """After a ``BrokenPipeError`` on stdout: point stdout at the null device (so the
    interpreter's final flush raises nothing) and return :data:`EXIT_STDOUT_CLOSED`; no
    traceback, as ``head`` expects of a good filter."""
    with suppress(OSError, ValueError, AttributeError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    return EXIT_STDOUT_CLOSED


def take_ctrl_c() -> None:
    """Make Ctrl-C reach this process: Python's own handler for SIGINT, and SIGINT unblocked.

    A process inherits its parent's disposition and mask of SIGINT: started from a parent
    that ignores it (a pool's worker, a shell's background job, a test runner's worker) or
    that had it blocked at the moment it spawned (multiprocessing blocks it in the spawning
    thread while it starts its resource tracker), Python installs no handler, or the signal
    stays pending, and the command runs to its end and exits 0 after a Ctrl-C. A command
    line takes it back at its start, so a Ctrl-C is never lost."""
    import signal

    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        with suppress(ValueError, OSError):      # not the main thread: leave it
            signal.signal(signal.SIGINT, signal.default_int_handler)
    if hasattr(signal, "pthread_sigmask"):
        with suppress(ValueError, OSError):
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is, so that its clean-up runs as for a Ctrl-C
    (a write in progress removes its temporary; a recorded history entry is reported)."""


#: exit status after SIGTERM: 128 + 15
EXIT_TERMINATED = 143


def take_sigterm() -> None:
    """Turn SIGTERM (a scheduler's or ``kill``'s polite stop) into :class:`Terminated`, so a
    command stops as it does on a Ctrl-C (nothing half-written left, one line, status
    :data:`EXIT_TERMINATED`) instead of dying on the spot."""
    import signal

    def terminated(signum, frame):
        raise Terminated()

    with suppress(ValueError, OSError):     # not the main thread: leave it
        signal.signal(signal.SIGTERM, terminated)


#: what a terminal that cannot show a character gets instead (the rest: ``?``)
PLAIN_TEXT = {"±": "+-", "—": "--", "–": "-", "−": "-", "→": "->", "←": "<-", "×": "x",
              "≤": "<=", "≥": ">=", "≈": "~", "…": "...", "°": " deg", "µ": "u", "²": "^2",
              "³": "^3", "√": "sqrt", "α": "alpha", "β": "beta", "γ": "gamma", "δ": "delta",
              "Δ": "Delta", "θ": "theta", "φ": "phi", "ψ": "psi", "σ": "sigma", "χ": "chi",
              "ν": "nu", "λ": "lambda", "ω": "omega", "π": "pi", "·": "*", "’": "'",
              "“": '"', "”": '"', "─": "-", "┐": "+", "┘": "+", "┼": "+", "├": "+",
              "►": ">", "é": "e", "ö": "o", "ü": "u"}


def _plain_text(err: UnicodeEncodeError):
    return "".join(PLAIN_TEXT.get(ch, "?") for ch in err.object[err.start:err.end]), err.end


codecs.register_error("cadra-plain-text", _plain_text)


def plain_text_streams() -> None:
    """A terminal whose encoding cannot show ``±``, ``α`` or ``—`` (``PYTHONIOENCODING=ascii``,
    an ISO-8859-1 locale) gets ``+-``, ``alpha`` and ``--`` (:data:`PLAIN_TEXT`) instead of a
    traceback: stdout and stderr are reconfigured to replace what they cannot encode."""
    for stream in (sys.stdout, sys.stderr):
        if stream is None or not hasattr(stream, "reconfigure"):
            continue
        try:
            "±αχ²—µ°".encode(stream.encoding or "ascii")
        except (UnicodeEncodeError, LookupError):
            with suppress(ValueError, OSError):
                stream.reconfigure(errors="cadra-plain-text")


def quiet_finalizers() -> None:
    """After an interrupt, drop what finalizers raise for the rest of the process.

    A signal raises where the program happens to be, possibly inside a library's constructor
    (llvmlite's ``OutputString`` was seen cut off before it had set its pointer); that
    half-built object's ``__del__`` then fails when the interpreter collects it, and Python
    prints "Exception ignored in ..." with a traceback after the command's one line. The
    process is ending on the user's request and nothing is left to clean up, so those
    reports are noise (:data:`sys.unraisablehook`)."""
    sys.unraisablehook = lambda unraisable: None


def console_main(prog: str, body, argv) -> int:
    """Run a console script's ``body(argv)`` to the conventions of docs/cli.md: Ctrl-C ends
    it with one line and status 130 (and is never lost: :func:`take_ctrl_c`), a closed
    stdout (``| head``) quietly with :data:`EXIT_STDOUT_CLOSED`, SIGTERM as Ctrl-C with
    :data:`EXIT_TERMINATED` (:func:`take_sigterm`), a terminal that cannot show
    a character with a plain-text stand-in (:func:`plain_text_streams`); returns the exit
    status."""
    from cadra.atomic import raise_swallowed_stop, watch_swallowed_stops

    take_ctrl_c()
    take_sigterm()
    watch_swallowed_stops()
    plain_text_streams()
    try:
        try:
            status = body(argv)
        except Exception:
            # a Ctrl-C that a finalizer swallowed can leave a library half-done (numba's
            # cache then fails to save a function whose compile it cut): the stop is the cause
            raise_swallowed_stop()
            raise
        raise_swallowed_stop()   # a Ctrl-C that a finalizer swallowed still ends it so
        sys.stdout.flush()   # a closed stdout shows here, inside the handler below
        return status
    except Terminated:
        quiet_finalizers()
        print(f"{prog}: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        quiet_finalizers()
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:   # stdout's reader went away (| head): quietly, 141
        return stdout_closed()


__all__ = ["EXIT_STDOUT_CLOSED", "EXIT_TERMINATED", "PLAIN_TEXT", "HelpFormatter", "Terminated",
           "add_verbosity", "add_version", "console_main", "join_number_lists", "number",
           "plain_text_streams", "quiet_finalizers", "stdout_closed", "take_ctrl_c",
           "take_sigterm", "warn",
           "write_error"]
